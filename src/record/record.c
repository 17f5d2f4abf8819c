/* Recordings (record.h): an append-only file of CRC-checked records. */
#include "stillheart/record.h"

#include <errno.h>
#include <fcntl.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/uio.h>
#include <unistd.h>

#define FILE_MAGIC "SHREC\r\n\x1a"
#define REC_MAGIC 0x52524853u /* "SHRR" little endian */
#define VERSION 1
#define FILE_HEADER 16
#define REC_HEADER 16
#define STREAM_PAYLOAD (7 * 4 + 64)
#define FRAME_META 24
#define SET_PAYLOAD (8 + 8 + 4 + 4 + 8 * SH_SYNC_MAX_CAMERAS)
#define MJPEG_SLACK (1u << 20)

/* ---- CRC-32 ---- */

static uint32_t crc_table[256];
static void crc_init(void)
{
    for (uint32_t i = 0; i < 256; i++) {
        uint32_t c = i;
        for (int k = 0; k < 8; k++) c = c & 1 ? 0xedb88320u ^ (c >> 1) : c >> 1;
        crc_table[i] = c;
    }
}

uint32_t sh_crc32(uint32_t crc, const void *data, size_t n)
{
    if (!crc_table[1]) crc_init(); /* idempotent: racing threads write the same values */
    const uint8_t *p = data;
    crc = ~crc;
    for (size_t i = 0; i < n; i++) crc = crc_table[(crc ^ p[i]) & 0xff] ^ (crc >> 8);
    return ~crc;
}

static void put32(uint8_t *p, uint32_t v)
{
    for (int i = 0; i < 4; i++) p[i] = (uint8_t)(v >> (8 * i));
}
static void put64(uint8_t *p, uint64_t v)
{
    for (int i = 0; i < 8; i++) p[i] = (uint8_t)(v >> (8 * i));
}
static uint32_t get32(const uint8_t *p)
{
    return (uint32_t)p[0] | (uint32_t)p[1] << 8 | (uint32_t)p[2] << 16 | (uint32_t)p[3] << 24;
}
static uint64_t get64(const uint8_t *p) { return (uint64_t)get32(p) | (uint64_t)get32(p + 4) << 32; }

/* ---- writer ---- */

struct sh_rec_writer {
    int fd;
    char path[4096];
    int failed;
    int have_stream[SH_REC_MAX_STREAMS];
};

sh_status sh_rec_writer_create(const char *dir, sh_rec_writer **out)
{
    if (!dir || !out) return sh_error_set(SH_EINVAL, "record: no folder");
    sh_rec_writer *w = calloc(1, sizeof *w);
    if (!w) return sh_error_set(SH_ENOMEM, "record: out of memory");
    if ((size_t)snprintf(w->path, sizeof w->path, "%s/%s", dir, SH_REC_FILE) >= sizeof w->path) {
        free(w);
        return sh_error_set(SH_EINVAL, "record: folder name too long");
    }
    if (mkdir(dir, 0777) < 0 && errno != EEXIST) {
        int e = errno;
        free(w);
        return sh_error_set(SH_EIO, "%s: cannot create: %s", dir, strerror(e));
    }
    w->fd = open(w->path, O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (w->fd < 0) {
        int e = errno;
        sh_status st = sh_error_set(SH_EIO, "%s: %s", w->path, e == EEXIST ? "a recording is there already" : strerror(e));
        free(w);
        return st;
    }
    uint8_t h[FILE_HEADER];
    memcpy(h, FILE_MAGIC, 8);
    put32(h + 8, VERSION);
    put32(h + 12, FILE_HEADER);
    if (write(w->fd, h, sizeof h) != (ssize_t)sizeof h) {
        int e = errno;
        close(w->fd);
        free(w);
        return sh_error_set(SH_EIO, "%s: write: %s", dir, strerror(e));
    }
    *out = w;
    return SH_OK;
}

/* One record in one writev: header, fixed part, optional data. */
static sh_status put_record(sh_rec_writer *w, uint32_t type, const uint8_t *fixed, size_t nfixed, const uint8_t *data,
                            size_t ndata)
{
    if (w->failed) return sh_error_set(SH_EIO, "%s: an earlier write failed", w->path);
    if (nfixed + ndata > UINT32_MAX) return sh_error_set(SH_ERANGE, "%s: record too large", w->path);
    uint8_t h[REC_HEADER];
    put32(h, REC_MAGIC);
    put32(h + 4, type);
    put32(h + 8, (uint32_t)(nfixed + ndata));
    uint32_t crc = sh_crc32(0, fixed, nfixed);
    if (ndata) crc = sh_crc32(crc, data, ndata);
    put32(h + 12, crc);
    struct iovec iov[3] = {{h, sizeof h}, {(void *)fixed, nfixed}, {(void *)data, ndata}};
    size_t total = sizeof h + nfixed + ndata, done = 0;
    int n = ndata ? 3 : 2, first = 0;
    while (done < total) {
        ssize_t r = writev(w->fd, iov + first, n - first);
        if (r < 0 && errno == EINTR) continue;
        if (r <= 0) {
            int e = r < 0 ? errno : ENOSPC;
            w->failed = 1;
            return sh_error_set(SH_EIO, "%s: write: %s", w->path, strerror(e));
        }
        done += (size_t)r;
        /* a short write (rare): advance the vectors */
        while (first < n && (size_t)r >= iov[first].iov_len) r -= (ssize_t)iov[first++].iov_len;
        if (first < n) {
            iov[first].iov_base = (uint8_t *)iov[first].iov_base + r;
            iov[first].iov_len -= (size_t)r;
        }
    }
    return SH_OK;
}

sh_status sh_rec_writer_stream(sh_rec_writer *w, const sh_rec_stream *s)
{
    if (!w || !s || s->camera < 0 || s->camera >= SH_REC_MAX_STREAMS)
        return sh_error_set(SH_EINVAL, "record: bad stream");
    uint8_t p[STREAM_PAYLOAD];
    memset(p, 0, sizeof p);
    put32(p, (uint32_t)s->camera);
    put32(p + 4, (uint32_t)s->format);
    put32(p + 8, (uint32_t)s->width);
    put32(p + 12, (uint32_t)s->height);
    put32(p + 16, (uint32_t)s->stride);
    put32(p + 20, (uint32_t)s->fps_num);
    put32(p + 24, (uint32_t)s->fps_den);
    memcpy(p + 28, s->source, strnlen(s->source, 63));
    sh_status st = put_record(w, SH_REC_STREAM, p, sizeof p, NULL, 0);
    if (st == SH_OK) w->have_stream[s->camera] = 1;
    return st;
}

sh_status sh_rec_writer_frame(sh_rec_writer *w, int camera, uint64_t sequence, int64_t ts, const sh_raw *raw)
{
    if (!w || !raw || camera < 0 || camera >= SH_REC_MAX_STREAMS || !w->have_stream[camera])
        return sh_error_set(SH_EINVAL, "record: frame of camera %d without its stream", camera);
    uint8_t p[FRAME_META];
    put32(p, (uint32_t)camera);
    put32(p + 4, 0);
    put64(p + 8, sequence);
    put64(p + 16, (uint64_t)ts);
    return put_record(w, SH_REC_FRAME, p, sizeof p, raw->data, raw->bytes);
}

sh_status sh_rec_writer_set(sh_rec_writer *w, const sh_frame_set *set)
{
    if (!w || !set) return sh_error_set(SH_EINVAL, "record: NULL set");
    uint8_t p[SET_PAYLOAD];
    memset(p, 0, sizeof p);
    put64(p, set->index);
    put64(p + 8, (uint64_t)set->time_ns);
    put32(p + 16, (set->triggered ? 1u : 0u) | (set->complete ? 2u : 0u));
    put32(p + 20, set->present);
    for (int c = 0; c < SH_SYNC_MAX_CAMERAS; c++)
        if (set->present & (1u << c)) put64(p + 24 + 8 * c, set->member[c].sequence);
    return put_record(w, SH_REC_SET, p, sizeof p, NULL, 0);
}

sh_status sh_rec_writer_close(sh_rec_writer *w)
{
    if (!w) return SH_OK;
    int failed = w->failed;
    sh_status st = SH_OK;
    if (fsync(w->fd) < 0 && errno != EINVAL) failed = 1;
    if (close(w->fd) < 0) failed = 1;
    if (failed) st = sh_error_set(SH_EIO, "%s: the recording is incomplete (write failed)", w->path);
    free(w);
    return st;
}

/* ---- reader ---- */

struct sh_rec_reader {
    FILE *file;
    int own;
    char name[4096];
    sh_rec_stream streams[SH_REC_MAX_STREAMS];
    int have[SH_REC_MAX_STREAMS];
    int nstreams;
    uint8_t *buf;
    size_t cap;
    int truncated;
    uint64_t skipped;
    long first_other; /* offset of the first record after the leading streams */
};

static size_t stream_bound(const sh_rec_stream *s)
{
    if (s->format == SH_RAW_MJPEG) return (size_t)s->width * (size_t)s->height * 3 + MJPEG_SLACK;
    return sh_raw_frame_size(s->format, s->width, s->height, s->stride) + MJPEG_SLACK;
}

static sh_status grow(sh_rec_reader *r, size_t need)
{
    if (need <= r->cap) return SH_OK;
    uint8_t *b = realloc(r->buf, need);
    if (!b) return sh_error_set(SH_ENOMEM, "%s: out of memory", r->name);
    r->buf = b;
    r->cap = need;
    return SH_OK;
}

static int parse_stream(const uint8_t *p, sh_rec_stream *s)
{
    memset(s, 0, sizeof *s);
    uint32_t cam = get32(p), fmt = get32(p + 4), w = get32(p + 8), h = get32(p + 12), stride = get32(p + 16);
    if (cam >= SH_REC_MAX_STREAMS || fmt >= SH_RAW_COUNT || !w || !h || w > SH_IMAGE_MAX_SIZE ||
        h > SH_IMAGE_MAX_SIZE || stride > 4u * SH_IMAGE_MAX_SIZE)
        return 0;
    s->camera = (int)cam;
    s->format = (sh_rawfmt)fmt;
    s->width = (int)w;
    s->height = (int)h;
    s->stride = (int)stride;
    s->fps_num = (int)(get32(p + 20) & 0x7fffffff);
    s->fps_den = (int)(get32(p + 24) & 0x7fffffff);
    memcpy(s->source, p + 28, 63);
    s->source[63] = 0;
    if (fmt != SH_RAW_MJPEG && !sh_raw_frame_size(s->format, s->width, s->height, s->stride)) return 0;
    return 1;
}

/* Reads one record into r->buf; 1 ok, 0 end/torn, -1 bad CRC or oversize (skipped). */
static int read_record(sh_rec_reader *r, uint32_t *type, uint32_t *len)
{
    uint8_t h[REC_HEADER];
    size_t got = fread(h, 1, sizeof h, r->file);
    if (got == 0 && feof(r->file)) return 0;
    if (got != sizeof h || get32(h) != REC_MAGIC) {
        r->truncated = 1;
        return 0;
    }
    *type = get32(h + 4);
    *len = get32(h + 8);
    size_t bound = 4096;
    for (int c = 0; c < SH_REC_MAX_STREAMS; c++)
        if (r->have[c] && stream_bound(&r->streams[c]) + FRAME_META > bound)
            bound = stream_bound(&r->streams[c]) + FRAME_META;
    if (*len > bound) {
        /* not a length any stream can have: the framing is not trustworthy */
        r->truncated = 1;
        return 0;
    }
    if (grow(r, *len ? *len : 1) != SH_OK) return 0;
    if (fread(r->buf, 1, *len, r->file) != *len) {
        r->truncated = 1;
        return 0;
    }
    if (sh_crc32(0, r->buf, *len) != get32(h + 12)) {
        r->skipped++;
        return -1;
    }
    return 1;
}

static int add_stream(sh_rec_reader *r, const uint8_t *p, uint32_t len, sh_rec_stream *out)
{
    sh_rec_stream s;
    if (len != STREAM_PAYLOAD || !parse_stream(p, &s)) return 0;
    if (!r->have[s.camera]) r->nstreams++;
    r->streams[s.camera] = s;
    r->have[s.camera] = 1;
    if (out) *out = s;
    return 1;
}

sh_status sh_rec_reader_open_file(FILE *file, const char *name, sh_rec_reader **out)
{
    if (!file || !out) return sh_error_set(SH_EINVAL, "recording: NULL argument");
    sh_rec_reader *r = calloc(1, sizeof *r);
    if (!r) return sh_error_set(SH_ENOMEM, "%s: out of memory", name);
    r->file = file;
    snprintf(r->name, sizeof r->name, "%s", name ? name : "recording");
    uint8_t h[FILE_HEADER];
    if (fread(h, 1, sizeof h, file) != sizeof h || memcmp(h, FILE_MAGIC, 8) || get32(h + 8) != VERSION ||
        get32(h + 12) != FILE_HEADER) {
        sh_status st = sh_error_set(SH_EFORMAT, "%s: not a stillheart recording (version %d)", r->name, VERSION);
        free(r);
        return st;
    }
    /* the leading stream records */
    for (;;) {
        long at = ftell(file);
        uint32_t type, len;
        int k = read_record(r, &type, &len);
        if (k == 1 && type == SH_REC_STREAM && add_stream(r, r->buf, len, NULL)) continue;
        r->truncated = 0;
        r->skipped = 0;
        if (at < 0 || fseek(file, at, SEEK_SET) != 0) {
            sh_rec_reader_close(r);
            return sh_error_set(SH_EIO, "%s: cannot seek", name);
        }
        r->first_other = at;
        break;
    }
    *out = r;
    return SH_OK;
}

sh_status sh_rec_reader_open(const char *path, sh_rec_reader **out)
{
    if (!path || !out) return sh_error_set(SH_EINVAL, "recording: no path");
    char file[4096];
    struct stat stt;
    if (stat(path, &stt) == 0 && S_ISDIR(stt.st_mode)) {
        if ((size_t)snprintf(file, sizeof file, "%s/%s", path, SH_REC_FILE) >= sizeof file)
            return sh_error_set(SH_EINVAL, "%s: path too long", path);
    } else {
        snprintf(file, sizeof file, "%s", path);
    }
    FILE *f = fopen(file, "rb");
    if (!f) return sh_error_set(SH_EIO, "%s: %s", file, strerror(errno));
    sh_status st = sh_rec_reader_open_file(f, file, out);
    if (st != SH_OK) {
        fclose(f);
        return st;
    }
    (*out)->own = 1;
    return SH_OK;
}

int sh_rec_reader_streams(const sh_rec_reader *r, const sh_rec_stream **streams)
{
    if (!r) return 0;
    if (streams) *streams = r->streams;
    return r->nstreams;
}

const sh_rec_stream *sh_rec_reader_stream(const sh_rec_reader *r, int camera)
{
    if (!r || camera < 0 || camera >= SH_REC_MAX_STREAMS || !r->have[camera]) return NULL;
    return &r->streams[camera];
}

sh_status sh_rec_reader_next(sh_rec_reader *r, sh_rec_record *rec)
{
    if (!r || !rec) return sh_error_set(SH_EINVAL, "recording: NULL argument");
    for (;;) {
        uint32_t type, len;
        int k = read_record(r, &type, &len);
        if (k == 0) return SH_EEOF;
        if (k < 0) continue;
        memset(rec, 0, sizeof *rec);
        const uint8_t *p = r->buf;
        if (type == SH_REC_STREAM) {
            if (!add_stream(r, p, len, &rec->stream)) {
                r->skipped++;
                continue;
            }
            rec->type = SH_REC_STREAM;
            return SH_OK;
        }
        if (type == SH_REC_FRAME) {
            uint32_t cam = len >= FRAME_META ? get32(p) : SH_REC_MAX_STREAMS;
            if (cam >= SH_REC_MAX_STREAMS || !r->have[cam]) {
                r->skipped++;
                continue;
            }
            const sh_rec_stream *s = &r->streams[cam];
            rec->type = SH_REC_FRAME;
            rec->camera = (int)cam;
            rec->sequence = get64(p + 8);
            rec->timestamp_ns = (int64_t)get64(p + 16);
            rec->raw.format = s->format;
            rec->raw.width = s->width;
            rec->raw.height = s->height;
            rec->raw.stride = s->stride;
            rec->raw.data = p + FRAME_META;
            rec->raw.bytes = len - FRAME_META;
            if (sh_raw_check(&rec->raw) != SH_OK) {
                r->skipped++;
                continue;
            }
            return SH_OK;
        }
        if (type == SH_REC_SET && len == SET_PAYLOAD) {
            rec->type = SH_REC_SET;
            sh_frame_set *f = &rec->set;
            f->index = get64(p);
            f->time_ns = (int64_t)get64(p + 8);
            uint32_t flags = get32(p + 16);
            f->triggered = (flags & 1) != 0;
            f->complete = (flags & 2) != 0;
            f->present = get32(p + 20) & ((1u << SH_SYNC_MAX_CAMERAS) - 1);
            for (int c = 0; c < SH_SYNC_MAX_CAMERAS; c++)
                if (f->present & (1u << c)) {
                    f->member[c].sequence = get64(p + 24 + 8 * c);
                    f->count++;
                }
            return SH_OK;
        }
        r->skipped++; /* unknown type or bad length: skipped (a later version's record) */
    }
}

int sh_rec_reader_truncated(const sh_rec_reader *r) { return r ? r->truncated : 0; }
uint64_t sh_rec_reader_skipped(const sh_rec_reader *r) { return r ? r->skipped : 0; }

void sh_rec_reader_close(sh_rec_reader *r)
{
    if (!r) return;
    if (r->own) fclose(r->file);
    free(r->buf);
    free(r);
}
