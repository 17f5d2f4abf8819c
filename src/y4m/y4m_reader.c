/* Y4M reader. Works on pipes: nothing here seeks, and a frame is read with fread straight into
 * the caller's planes, so a frame costs a few large reads and no copy. On a regular file the
 * header's frame size is checked against the file's size at open, before a caller allocates a
 * frame: a 184 KB file cannot make anyone allocate 16384x16384 frames. On a pipe, where that
 * cannot be known, the bound on a frame's pixels (the caller's, or SH_FRAME_PIXELS_DEFAULT)
 * does it, on files too. */
#include "y4m_internal.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

/* A larger stdio buffer keeps the syscall count per frame low when rows are padded (one fread
 * per row then, served from this buffer). */
#define READ_BUFFER (1u << 20)
/* Bytes read before the magic is checked: enough for the signatures y4m_sniff.c knows, fewer
 * than the shortest valid header ("YUV4MPEG2 W1 H1\n"), so a valid stream has no newline in them. */
#define Y4M_SNIFF 12

struct sh_y4m_reader {
    FILE *file;
    int owns_file;      /* fclose on close (not for stdin or a caller's FILE) */
    char *buffer;       /* our setvbuf buffer (only on files we own), freed after fclose */
    char *name;
    sh_y4m_header header;
    int frames;         /* delivered so far */
    sh_status failed;   /* sticky: after a damaged frame the stream position is unknown */
    long long pos;      /* bytes consumed (header, FRAME lines, planes) */
    long long size;     /* of a regular file at open from where we began, -1 otherwise */
    long long base;     /* the file offset where we began (stdin may be redirected mid-file) */
    sh_y4m_damage damage; /* valid when failed == SH_EFORMAT */
    char line[Y4M_MAX_HEADER + 1];
};

/* Reads one line (without '\n') of at most cap bytes. Returns its length, -1 at EOF before any
 * byte, -2 when longer than cap, -3 at EOF inside the line, -4 on a read error. */
static long read_line(FILE *f, char *buf, size_t cap)
{
    size_t n = 0;
    for (;;) {
        int c = getc(f);
        if (c == EOF) {
            if (ferror(f)) return -4;
            return n == 0 ? -1 : -3;
        }
        if (c == '\n') return (long)n;
        if (n == cap) return -2;
        buf[n++] = (char)c;
    }
}

static sh_status open_common(FILE *f, const char *name, int owns, char *vbuf, long long max_pixels,
                             sh_y4m_reader **out)
{
    sh_y4m_reader *r = calloc(1, sizeof *r);
    char *copy = r ? strdup(name) : NULL;
    if (!r || !copy) {
        free(r);
        if (owns) fclose(f);
        free(vbuf);
        return sh_error_set(SH_ENOMEM, "%s: out of memory", name);
    }
    r->file = f;
    r->owns_file = owns;
    r->buffer = vbuf;
    r->name = copy;

    /* The magic first, on its own: another format's bytes are refused as that format, not as a
     * Y4M header that is too long or has no newline. A newline ends the line only while the bytes
     * still agree with the magic: a PNG's signature holds one. */
    size_t k = 0;
    int c = 0;
    while (k < Y4M_SNIFF && (c = getc(f)) != EOF) {
        if (c == '\n' && !memcmp(r->line, "YUV4MPEG2 ", k < 10 ? k : 10)) break;
        r->line[k++] = (char)c;
    }
    long n;
    if (k == 0 && c == EOF) n = ferror(f) ? -4 : -1;
    else if (k < 10 || memcmp(r->line, "YUV4MPEG2 ", 10)) n = -5;
    else if (k < Y4M_SNIFF) n = c == '\n' ? (long)k : ferror(f) ? -4 : -3;
    else if ((n = read_line(f, r->line + k, Y4M_MAX_HEADER - k)) >= 0) n += (long)k;
    else if (n == -1) n = -3;
    sh_status st = SH_OK;
    if (n == -5) st = y4m_refuse_not_y4m((const unsigned char *)r->line, k, name);
    else if (n == -1) st = sh_error_set(SH_EFORMAT, "%s: empty file, no Y4M header", name);
    else if (n == -2) st = sh_error_set(SH_EFORMAT, "%s: Y4M header longer than %d bytes", name,
                                        Y4M_MAX_HEADER);
    else if (n == -3) st = sh_error_set(SH_EFORMAT, "%s: Y4M header not terminated", name);
    else if (n == -4) st = sh_error_set(SH_EIO, "%s: read error: %s", name, strerror(errno));
    else st = y4m_header_parse_named(r->line, (size_t)n, name, &r->header);
    r->pos = n + 1;
    r->size = -1;
    struct stat sb;
    int fd = st == SH_OK ? fileno(f) : -1;
    if (fd >= 0 && fstat(fd, &sb) == 0 && S_ISREG(sb.st_mode)) {
        long long at = (long long)ftello(f);
        r->base = at >= r->pos ? at - r->pos : 0;
        r->size = (long long)sb.st_size - r->base;
        long long rest = r->size - r->pos;
        const sh_y4m_header *h = &r->header;
        long long frame = (long long)sh_image_packed_size(h->format, h->width, h->height) + 6;
        if (rest > 0 && rest < frame)
            st = sh_error_set(SH_EFORMAT,
                              "%s: the header promises %dx%d %s frames of %lld bytes, the file holds %lld "
                              "after its header: not one whole frame (a damaged header or a cut file)",
                              name, h->width, h->height, sh_pixfmt_name(h->format), frame - 6, rest);
    }
    /* a pipe's size is unknown, and a file large enough for one frame may still ask for more
     * than anyone should allocate for a stream */
    if (st == SH_OK) st = sh_image_check_pixels(name, r->header.width, r->header.height, max_pixels);
    if (st != SH_OK) {
        sh_y4m_reader_close(r);
        return st;
    }
    *out = r;
    return SH_OK;
}

sh_status sh_y4m_reader_open(const char *path, sh_y4m_reader **out)
{
    return sh_y4m_reader_open_max(path, SH_FRAME_PIXELS_DEFAULT, out);
}

sh_status sh_y4m_reader_open_max(const char *path, long long max_pixels, sh_y4m_reader **out)
{
    if (!path || !out) return sh_error_set(SH_EINVAL, "y4m: missing argument");
    *out = NULL;
    int is_stdin = strcmp(path, "-") == 0;
    FILE *f = is_stdin ? stdin : fopen(path, "rb");
    if (!f) return sh_error_set(SH_EIO, "%s: %s", path, strerror(errno));
    /* stdin keeps its own buffer: it may already be in use, and it outlives this reader. */
    char *vbuf = is_stdin ? NULL : malloc(READ_BUFFER);
    if (vbuf && setvbuf(f, vbuf, _IOFBF, READ_BUFFER) != 0) {
        free(vbuf);
        vbuf = NULL;
    }
    return open_common(f, is_stdin ? "<stdin>" : path, !is_stdin, vbuf, max_pixels, out);
}

sh_status sh_y4m_reader_open_file(FILE *file, const char *name, sh_y4m_reader **out)
{
    if (!file || !out) return sh_error_set(SH_EINVAL, "y4m: missing argument");
    *out = NULL;
    return open_common(file, name ? name : "y4m", 0, NULL, SH_FRAME_PIXELS_DEFAULT, out);
}

const sh_y4m_header *sh_y4m_reader_header(const sh_y4m_reader *reader)
{
    return reader ? &reader->header : NULL;
}

int sh_y4m_reader_frame_index(const sh_y4m_reader *reader)
{
    return reader ? reader->frames : 0;
}

long long sh_y4m_reader_whole_frames(const sh_y4m_reader *r)
{
    if (!r || r->size < 0) return -1;
    const sh_y4m_header *h = &r->header;
    long long frame = (long long)sh_image_packed_size(h->format, h->width, h->height) + 6;
    long long rest = r->size - r->pos;
    return rest > 0 ? rest / frame : 0;
}

int sh_y4m_reader_damage(const sh_y4m_reader *r, sh_y4m_damage *d)
{
    if (!r || r->failed != SH_EFORMAT) return 0;
    if (d) *d = r->damage;
    return 1;
}

/* The FRAME line: "FRAME" then nothing or a space and parameters we skip. */
static sh_status read_frame_line(sh_y4m_reader *r)
{
    long n = read_line(r->file, r->line, Y4M_MAX_HEADER);
    if (n >= 0) r->pos += n + 1;
    if (n == -1) return SH_EEOF;
    if (n == -4)
        return sh_error_set(SH_EIO, "%s: frame %d: read error: %s", r->name, r->frames,
                            strerror(errno));
    if (n == -3)
        return sh_error_set(SH_EFORMAT, "%s: frame %d: truncated FRAME line", r->name,
                            r->frames);
    if (n == -2 || n < 5 || memcmp(r->line, "FRAME", 5) != 0 || (n > 5 && r->line[5] != ' '))
        return sh_error_set(SH_EFORMAT, "%s: frame %d: bad FRAME line", r->name, r->frames);
    return SH_OK;
}

static sh_status read_planes(sh_y4m_reader *r, sh_image *img)
{
    size_t want = sh_image_packed_size(img->format, img->width, img->height), got = 0;
    for (int p = 0; p < img->num_planes; p++) {
        const sh_plane *pl = &img->plane[p];
        size_t row = (size_t)pl->width * (size_t)sh_pixfmt_channels(img->format);
        if ((size_t)pl->stride == row) {
            size_t bytes = row * (size_t)pl->height;
            size_t n = fread(pl->data, 1, bytes, r->file);
            got += n;
            r->pos += (long long)n;
            if (n != bytes) goto short_read;
        } else {
            for (int y = 0; y < pl->height; y++) {
                size_t n = fread(pl->data + (size_t)y * (size_t)pl->stride, 1, row, r->file);
                got += n;
                r->pos += (long long)n;
                if (n != row) goto short_read;
            }
        }
    }
    return SH_OK;
short_read:
    if (ferror(r->file))
        return sh_error_set(SH_EIO, "%s: frame %d: read error: %s", r->name, r->frames,
                            strerror(errno));
    return sh_error_set(SH_EFORMAT, "%s: frame %d truncated (%zu of %zu bytes)", r->name,
                        r->frames, got, want);
}

/* Fills r->damage for a frame that could not be read from byte `at`, and says in the message
 * how much of the file lies beyond it: the caller must know whether it lost a torn tail or the
 * rest of a recording. */
static void note_damage(sh_y4m_reader *r, long long at)
{
    const sh_y4m_header *h = &r->header;
    long long frame = (long long)sh_image_packed_size(h->format, h->width, h->height) + 6;
    sh_y4m_damage *d = &r->damage;
    d->frame = r->frames;
    d->offset = at;
    d->lost = -1;
    d->frames_lost = -1;
    struct stat sb;
    int fd = r->size >= 0 ? fileno(r->file) : -1;
    if (fd >= 0 && fstat(fd, &sb) == 0) {
        long long size = (long long)sb.st_size - r->base; /* now: the file may have grown */
        d->lost = size > at ? size - at : 0;
        d->frames_lost = (d->lost + frame - 1) / frame;
    }
    char what[512];
    snprintf(what, sizeof what, "%s", sh_error_message());
    if (d->lost >= 0)
        sh_error_set(SH_EFORMAT, "%s at byte %lld; %lld bytes (%lld frame%s) from there to the end not read", what,
                     at, d->lost, d->frames_lost, d->frames_lost == 1 ? "" : "s");
    else
        sh_error_set(SH_EFORMAT, "%s at byte %lld", what, at);
}

sh_status sh_y4m_reader_read(sh_y4m_reader *reader, sh_image *img)
{
    if (!reader || !img) return sh_error_set(SH_EINVAL, "y4m: missing argument");
    const sh_y4m_header *h = &reader->header;
    if (img->format != h->format || img->width != h->width || img->height != h->height ||
        !img->plane[0].data)
        return sh_error_set(SH_EINVAL, "%s: image is %s %dx%d, stream is %s %dx%d", reader->name,
                            sh_pixfmt_name(img->format), img->width, img->height,
                            sh_pixfmt_name(h->format), h->width, h->height);
    if (reader->failed == SH_EEOF) return SH_EEOF;
    if (reader->failed)
        return sh_error_set(reader->failed, "%s: frame %d: stream already failed", reader->name,
                            reader->frames);
    long long at = reader->pos;
    sh_status st = read_frame_line(reader);
    if (st == SH_OK) st = read_planes(reader, img);
    if (st != SH_OK) {
        reader->failed = st;
        if (st == SH_EFORMAT) note_damage(reader, at);
        return st;
    }
    img->siting = h->siting;
    reader->frames++;
    return SH_OK;
}

void sh_y4m_reader_close(sh_y4m_reader *reader)
{
    if (!reader) return;
    if (reader->owns_file) fclose(reader->file);
    free(reader->buffer);
    free(reader->name);
    free(reader);
}
