/* Y4M writer: the header at open, then "FRAME\n" and the packed planes per frame. */
#include "y4m_internal.h"

#include <errno.h>
#include <fcntl.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define WRITE_BUFFER (1u << 20)

struct sh_y4m_writer {
    FILE *file;
    int owns_file;
    char *buffer;
    char *name;
    sh_y4m_header header;
    int frames;
};

static sh_status writer_free(sh_y4m_writer *w, sh_status st)
{
    if (w->owns_file) fclose(w->file);
    free(w->buffer);
    free(w->name);
    free(w);
    return st;
}

static sh_status open_common(FILE *f, const char *name, int owns, char *vbuf,
                             const sh_y4m_header *header, sh_y4m_writer **out)
{
    sh_y4m_writer *w = calloc(1, sizeof *w);
    char *copy = w ? strdup(name) : NULL;
    if (!w || !copy) {
        free(w);
        if (owns) fclose(f);
        free(vbuf);
        return sh_error_set(SH_ENOMEM, "%s: out of memory", name);
    }
    w->file = f;
    w->owns_file = owns;
    w->buffer = vbuf;
    w->name = copy;
    w->header = *header;

    char line[Y4M_MAX_HEADER + 64];
    int n = y4m_header_format(header, line, sizeof line);
    if (n < 0)
        return writer_free(w, sh_error_set(SH_EINVAL, "%s: cannot write a Y4M header for %s %dx%d",
                                           name, sh_pixfmt_name(header->format), header->width,
                                           header->height));
    if (fwrite(line, 1, (size_t)n, f) != (size_t)n)
        return writer_free(w, sh_error_set(SH_EIO, "%s: write error: %s", name, strerror(errno)));
    *out = w;
    return SH_OK;
}

sh_status sh_y4m_writer_open(const char *path, const sh_y4m_header *header, sh_y4m_writer **out)
{
    if (!path || !header || !out) return sh_error_set(SH_EINVAL, "y4m: missing argument");
    *out = NULL;
    int is_stdout = strcmp(path, "-") == 0;
    FILE *f = is_stdout ? stdout : fopen(path, "wb");
    if (!f) return sh_error_set(SH_EIO, "%s: %s", path, strerror(errno));
    char *vbuf = is_stdout ? NULL : malloc(WRITE_BUFFER);
    if (vbuf && setvbuf(f, vbuf, _IOFBF, WRITE_BUFFER) != 0) {
        free(vbuf);
        vbuf = NULL;
    }
    return open_common(f, is_stdout ? "<stdout>" : path, !is_stdout, vbuf, header, out);
}

sh_status sh_y4m_writer_open_new(const char *path, const sh_y4m_header *header, sh_y4m_writer **out)
{
    if (!path || !header || !out) return sh_error_set(SH_EINVAL, "y4m: missing argument");
    *out = NULL;
    int fd = open(path, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0640);
    if (fd < 0)
        return sh_error_set(SH_EIO, "%s: %s", path, errno == EEXIST ? "exists (never written over)" : strerror(errno));
    FILE *f = fdopen(fd, "wb");
    if (!f) {
        int e = errno;
        close(fd);
        return sh_error_set(SH_EIO, "%s: %s", path, strerror(e));
    }
    char *vbuf = malloc(WRITE_BUFFER);
    if (vbuf && setvbuf(f, vbuf, _IOFBF, WRITE_BUFFER) != 0) {
        free(vbuf);
        vbuf = NULL;
    }
    return open_common(f, path, 1, vbuf, header, out);
}

sh_status sh_y4m_writer_flush(sh_y4m_writer *writer)
{
    if (!writer) return sh_error_set(SH_EINVAL, "y4m: missing argument");
    if (fflush(writer->file) != 0 || ferror(writer->file))
        return sh_error_set(SH_EIO, "%s: write error: %s", writer->name, strerror(errno));
    return SH_OK;
}

int sh_y4m_writer_fd(const sh_y4m_writer *writer) { return writer ? fileno(writer->file) : -1; }

sh_status sh_y4m_writer_open_file(FILE *file, const char *name, const sh_y4m_header *header,
                                  sh_y4m_writer **out)
{
    if (!file || !header || !out) return sh_error_set(SH_EINVAL, "y4m: missing argument");
    *out = NULL;
    return open_common(file, name ? name : "y4m", 0, NULL, header, out);
}

sh_status sh_y4m_writer_write(sh_y4m_writer *writer, const sh_image *img)
{
    if (!writer || !img) return sh_error_set(SH_EINVAL, "y4m: missing argument");
    const sh_y4m_header *h = &writer->header;
    if (img->format != h->format || img->width != h->width || img->height != h->height)
        return sh_error_set(SH_EINVAL, "%s: image is %s %dx%d, stream is %s %dx%d", writer->name,
                            sh_pixfmt_name(img->format), img->width, img->height,
                            sh_pixfmt_name(h->format), h->width, h->height);
    FILE *f = writer->file;
    int ok = fwrite("FRAME\n", 1, 6, f) == 6;
    for (int p = 0; ok && p < img->num_planes; p++) {
        const sh_plane *pl = &img->plane[p];
        size_t row = (size_t)pl->width * (size_t)sh_pixfmt_channels(img->format);
        if ((size_t)pl->stride == row) {
            size_t bytes = row * (size_t)pl->height;
            ok = fwrite(pl->data, 1, bytes, f) == bytes;
        } else {
            for (int y = 0; ok && y < pl->height; y++)
                ok = fwrite(pl->data + (size_t)y * (size_t)pl->stride, 1, row, f) == row;
        }
    }
    if (!ok)
        return sh_error_set(SH_EIO, "%s: frame %d: write error: %s", writer->name, writer->frames,
                            strerror(errno));
    writer->frames++;
    return SH_OK;
}

sh_status sh_y4m_writer_close(sh_y4m_writer *writer)
{
    if (!writer) return SH_OK;
    sh_status st = SH_OK;
    /* The last buffered frames reach the disk only here: a full disk shows up now. */
    if (fflush(writer->file) != 0 || ferror(writer->file))
        st = sh_error_set(SH_EIO, "%s: write error: %s", writer->name, strerror(errno));
    if (writer->owns_file) {
        int rc = fclose(writer->file);
        if (rc != 0 && st == SH_OK)
            st = sh_error_set(SH_EIO, "%s: close failed: %s", writer->name, strerror(errno));
    }
    writer->owns_file = 0;
    return writer_free(writer, st);
}
