/* Recordings (record.h): an append-only file of CRC-checked records. */
#include "stillheart/record.h"

#include <errno.h>
#include <fcntl.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <sys/uio.h>
#include <unistd.h>

#define FILE_MAGIC "SHREC\r\n\x1a"
#define REC_MAGIC 0x52524853u /* "SHRR" little endian */
#define VERSION 2 /* 1: the CRC covered the payload only (still read) */
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
    /* sh_rec_writer_set_sync: the writer hands a sync request to a thread of its own every
     * sync_ms, because fdatasync can take tens of ms on an SD card and the writer is the capture
     * loop, which must not miss a frame for it */
    int64_t sync_ns, last_request;
    int sync_started, sync_stop, sync_failed, sync_errno;
    unsigned requested, synced;
    pthread_t sync_thread;
    pthread_mutex_t mu;
    pthread_cond_t cv;
};

static void *sync_thread(void *arg)
{
    sh_rec_writer *w = arg;
    pthread_mutex_lock(&w->mu);
    for (;;) {
        while (w->synced == w->requested && !w->sync_stop) pthread_cond_wait(&w->cv, &w->mu);
        if (w->synced == w->requested) break;
        unsigned upto = w->requested;
        pthread_mutex_unlock(&w->mu);
        int rc = fdatasync(w->fd), e = errno;
        pthread_mutex_lock(&w->mu);
        if (rc != 0 && e != EINVAL && !w->sync_failed++) w->sync_errno = e; /* EINVAL: a pipe or device */
        w->synced = upto;
    }
    pthread_mutex_unlock(&w->mu);
    return NULL;
}

sh_status sh_rec_writer_set_sync(sh_rec_writer *w, int sync_ms)
{
    if (!w || sync_ms < 0) return sh_error_set(SH_EINVAL, "record: bad sync interval");
    if (w->sync_started) return sh_error_set(SH_EINVAL, "%s: the sync interval is set already", w->path);
    w->sync_ns = (int64_t)sync_ms * 1000000;
    if (pthread_mutex_init(&w->mu, NULL) != 0) return sh_error_set(SH_ENOMEM, "record: no mutex");
    if (pthread_cond_init(&w->cv, NULL) != 0) {
        pthread_mutex_destroy(&w->mu);
        return sh_error_set(SH_ENOMEM, "record: no condition variable");
    }
    if (pthread_create(&w->sync_thread, NULL, sync_thread, w) != 0) {
        pthread_cond_destroy(&w->cv);
        pthread_mutex_destroy(&w->mu);
        return sh_error_set(SH_ENOMEM, "%s: cannot start the thread that syncs it", w->path);
    }
    w->sync_started = 1;
    w->last_request = sh_monotonic_ns();
    return SH_OK;
}

/* After a record is written: a sync request when the interval has passed since the last one. */
static void request_sync(sh_rec_writer *w)
{
    if (!w->sync_started) return;
    int64_t now = sh_monotonic_ns();
    if (now - w->last_request < w->sync_ns) return;
    w->last_request = now;
    pthread_mutex_lock(&w->mu);
    w->requested++;
    pthread_cond_signal(&w->cv);
    pthread_mutex_unlock(&w->mu);
}

/* Stops the sync thread (after the sync it is doing); 0 when a sync failed. */
static int stop_sync(sh_rec_writer *w)
{
    if (!w->sync_started) return 1;
    pthread_mutex_lock(&w->mu);
    w->sync_stop = 1;
    pthread_cond_signal(&w->cv);
    pthread_mutex_unlock(&w->mu);
    pthread_join(w->sync_thread, NULL);
    pthread_cond_destroy(&w->cv);
    pthread_mutex_destroy(&w->mu);
    w->sync_started = 0;
    return !w->sync_failed;
}

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
    uint32_t crc = sh_crc32(sh_crc32(0, h + 4, 8), fixed, nfixed);
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
    request_sync(w);
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
    int failed = w->failed, synced = stop_sync(w), e = w->sync_errno;
    sh_status st = SH_OK;
    if (fsync(w->fd) < 0 && errno != EINVAL) failed = 1;
    if (close(w->fd) < 0) failed = 1;
    if (failed) st = sh_error_set(SH_EIO, "%s: the recording is incomplete (write failed)", w->path);
    else if (!synced) st = sh_error_set(SH_EIO, "%s: fdatasync failed (%s): what was written may not be on disk",
                                        w->path, strerror(e));
    free(w);
    return st;
}

/* ---- reader ---- */

struct sh_rec_reader {
    FILE *file;
    int own;
    char name[4096];
    int version;
    sh_rec_stream streams[SH_REC_MAX_STREAMS];
    int have[SH_REC_MAX_STREAMS];
    int nstreams;
    uint8_t *buf;
    size_t cap;
    long long pos;     /* where the file is, as we moved it */
    long long rec_at;  /* where the record last read begins */
    int truncated;
    uint64_t skipped;
    uint64_t lost_bytes;
};

static size_t stream_bound(const sh_rec_stream *s)
{
    if (s->format == SH_RAW_MJPEG) return (size_t)s->width * (size_t)s->height * 3 + MJPEG_SLACK;
    return sh_raw_frame_size(s->format, s->width, s->height, s->stride) + MJPEG_SLACK;
}

/* The longest payload any known stream can have: a length above it is damage. */
static size_t len_bound(const sh_rec_reader *r)
{
    size_t bound = 4096;
    for (int c = 0; c < SH_REC_MAX_STREAMS; c++)
        if (r->have[c] && stream_bound(&r->streams[c]) + FRAME_META > bound)
            bound = stream_bound(&r->streams[c]) + FRAME_META;
    return bound;
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

enum { AT_RECORD = 1, AT_END = 0, AT_DAMAGE = -1, AT_SHORT = -2 };

/* The record at offset p into r->buf, the file left after it: AT_RECORD; AT_END when the file
 * ends at p; AT_SHORT when the file ends inside what the header promises (a torn record, if
 * nothing good follows); AT_DAMAGE when the magic, the length or the CRC is wrong. */
static int record_at(sh_rec_reader *r, long long p, uint32_t *type, uint32_t *len)
{
    if (p != r->pos) {
        if (fseeko(r->file, (off_t)p, SEEK_SET) != 0) return AT_DAMAGE;
        r->pos = p;
    }
    uint8_t h[REC_HEADER];
    size_t got = fread(h, 1, sizeof h, r->file);
    r->pos += (long long)got;
    if (got == 0) return AT_END;
    if (got < 4 ? memcmp(h, "SHRR", got) == 0 : get32(h) == REC_MAGIC) {
        if (got != sizeof h) return AT_SHORT;
    } else {
        return AT_DAMAGE;
    }
    *type = get32(h + 4);
    *len = get32(h + 8);
    if (*len > len_bound(r) || grow(r, *len ? *len : 1) != SH_OK) return AT_DAMAGE;
    got = fread(r->buf, 1, *len, r->file);
    r->pos += (long long)got;
    if (got != *len) return AT_SHORT;
    uint32_t crc = r->version >= 2 ? sh_crc32(0, h + 4, 8) : 0;
    return sh_crc32(crc, r->buf, *len) == get32(h + 12) ? AT_RECORD : AT_DAMAGE;
}

/* Resync: the first offset from `from` on where a record whose CRC holds begins (read into
 * r->buf), or -1. *magics counts the record magics passed over that did not hold: each was
 * the start of a record, damaged or cut. */
static long long next_record(sh_rec_reader *r, long long from, uint32_t *type, uint32_t *len, uint64_t *magics)
{
    uint8_t chunk[8192];
    for (long long p = from;;) {
        if (fseeko(r->file, (off_t)p, SEEK_SET) != 0) return -1;
        size_t n = fread(chunk, 1, sizeof chunk, r->file);
        r->pos = p + (long long)n;
        for (size_t i = 0; i + 4 <= n; i++) {
            if (get32(chunk + i) != REC_MAGIC) continue;
            if (record_at(r, p + (long long)i, type, len) == AT_RECORD) return p + (long long)i;
            (*magics)++;
        }
        if (n < sizeof chunk) return -1;
        p += (long long)n - 3; /* a magic across the chunk's end is seen in the next one */
    }
}

/* The next record whose CRC holds, into r->buf (1), or 0 at the end. Damage is skipped up to
 * the next record whose CRC holds and counted (the damaged record and every record magic in
 * the bytes skipped; the bytes); a record cut by the end of the file with nothing good after it
 * is the torn tail of a writer that was stopped. */
static int read_record(sh_rec_reader *r, uint32_t *type, uint32_t *len)
{
    long long at = r->pos;
    int k = record_at(r, at, type, len);
    if (k == AT_RECORD || k == AT_END) {
        r->rec_at = at;
        return k;
    }
    uint64_t magics = 0;
    long long next = next_record(r, at + 1, type, len, &magics);
    long long end = next;
    if (end < 0) {
        end = fseeko(r->file, 0, SEEK_END) == 0 ? (long long)ftello(r->file) : at;
        r->pos = end;
    }
    r->lost_bytes += end > at ? (uint64_t)(end - at) : 0;
    if (next < 0 && k == AT_SHORT && !magics) {
        r->truncated = 1;
        return 0;
    }
    r->skipped += 1 + magics;
    if (next < 0) return 0;
    r->rec_at = next;
    return 1;
}

/* A record whose CRC holds but whose content cannot be used. */
static void skip_content(sh_rec_reader *r, uint32_t len)
{
    r->skipped++;
    r->lost_bytes += REC_HEADER + (uint64_t)len;
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
    if (fread(h, 1, sizeof h, file) != sizeof h || memcmp(h, FILE_MAGIC, 8) || get32(h + 12) != FILE_HEADER ||
        get32(h + 8) < 1 || get32(h + 8) > VERSION) {
        int known = !memcmp(h, FILE_MAGIC, 8) && get32(h + 12) == FILE_HEADER;
        sh_status st = known ? sh_error_set(SH_EFORMAT, "%s: recording version %u, this reader knows 1 to %d", r->name,
                                            (unsigned)get32(h + 8), VERSION)
                             : sh_error_set(SH_EFORMAT, "%s: not a stillheart recording (damaged header?)", r->name);
        free(r);
        return st;
    }
    r->version = (int)get32(h + 8);
    long long at = (long long)ftello(file);
    if (at < 0) { /* resync seeks: a pipe cannot be read */
        free(r);
        return sh_error_set(SH_EINVAL, "%s: a recording is read from a file that can seek", name);
    }
    r->pos = at;
    /* the leading stream records; the first other record is read again by the first next() */
    for (;;) {
        uint32_t type, len;
        int k = read_record(r, &type, &len);
        if (k == 1 && type == SH_REC_STREAM && add_stream(r, r->buf, len, NULL)) continue;
        if (k == 0) break;
        if (fseeko(file, (off_t)r->rec_at, SEEK_SET) != 0) {
            sh_rec_reader_close(r);
            return sh_error_set(SH_EIO, "%s: cannot seek", name);
        }
        r->pos = r->rec_at;
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
        if (!read_record(r, &type, &len)) return SH_EEOF;
        memset(rec, 0, sizeof *rec);
        const uint8_t *p = r->buf;
        if (type == SH_REC_STREAM) {
            if (!add_stream(r, p, len, &rec->stream)) {
                skip_content(r, len);
                continue;
            }
            rec->type = SH_REC_STREAM;
            return SH_OK;
        }
        if (type == SH_REC_FRAME) {
            uint32_t cam = len >= FRAME_META ? get32(p) : SH_REC_MAX_STREAMS;
            if (cam >= SH_REC_MAX_STREAMS || !r->have[cam]) {
                skip_content(r, len);
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
                skip_content(r, len);
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
        skip_content(r, len); /* unknown type or bad length: skipped (a later version's record) */
    }
}

int sh_rec_reader_truncated(const sh_rec_reader *r) { return r ? r->truncated : 0; }
uint64_t sh_rec_reader_skipped(const sh_rec_reader *r) { return r ? r->skipped : 0; }
uint64_t sh_rec_reader_lost_bytes(const sh_rec_reader *r) { return r ? r->lost_bytes : 0; }
int sh_rec_reader_version(const sh_rec_reader *r) { return r ? r->version : 0; }

void sh_rec_reader_close(sh_rec_reader *r)
{
    if (!r) return;
    if (r->own) fclose(r->file);
    free(r->buf);
    free(r);
}
