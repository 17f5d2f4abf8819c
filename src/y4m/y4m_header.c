/* The YUV4MPEG2 header line: parsing (tolerant of tags we do not know, strict about the ones
 * we need) and formatting (the writer's canonical tag order, extra tags appended verbatim). */
#include "y4m_internal.h"

#include <limits.h>
#include <stdio.h>
#include <string.h>

#define MAGIC "YUV4MPEG2"
/* the largest frame stillheart can hold (image.h) */
#define MAX_DIM SH_IMAGE_MAX_SIZE

/* Parses a decimal integer filling all of [s, s+len); no sign, no overflow past INT_MAX. */
static int parse_uint(const char *s, size_t len, int *out)
{
    if (len == 0) return 0;
    long v = 0;
    for (size_t i = 0; i < len; i++) {
        if (s[i] < '0' || s[i] > '9') return 0;
        v = v * 10 + (s[i] - '0');
        if (v > INT_MAX) return 0;
    }
    *out = (int)v;
    return 1;
}

/* "n:d" with both parts decimal. */
static int parse_ratio(const char *s, size_t len, int *num, int *den)
{
    const char *colon = memchr(s, ':', len);
    if (!colon) return 0;
    size_t nlen = (size_t)(colon - s);
    return parse_uint(s, nlen, num) && parse_uint(colon + 1, len - nlen - 1, den);
}

/* The C tag's value (after the 'C'). Returns 0 for colour spaces we do not read. */
static int parse_colour(const char *s, size_t len, sh_y4m_header *h)
{
    static const struct {
        const char *name;
        sh_pixfmt format;
        sh_chroma_siting siting;
    } table[] = {
        {"420jpeg", SH_PIX_I420, SH_CHROMA_CENTER},
        {"420", SH_PIX_I420, SH_CHROMA_CENTER},
        {"420mpeg2", SH_PIX_I420, SH_CHROMA_LEFT},
        {"420paldv", SH_PIX_I420, SH_CHROMA_PALDV},
        {"444", SH_PIX_YUV444, SH_CHROMA_CENTER},
        {"mono", SH_PIX_GRAY8, SH_CHROMA_CENTER},
    };
    for (size_t i = 0; i < sizeof table / sizeof table[0]; i++) {
        if (strlen(table[i].name) == len && memcmp(table[i].name, s, len) == 0) {
            h->format = table[i].format;
            h->siting = table[i].siting;
            return 1;
        }
    }
    return 0;
}

/* Appends one tag to header->extra, space separated. */
static int append_extra(sh_y4m_header *h, const char *tag, size_t len)
{
    size_t used = strlen(h->extra);
    size_t need = used + (used ? 1 : 0) + len + 1;
    if (need > sizeof h->extra) return 0;
    if (used) h->extra[used++] = ' ';
    memcpy(h->extra + used, tag, len);
    h->extra[used + len] = '\0';
    return 1;
}

/* Which tags a header has given so far: each may appear once. */
typedef struct {
    int w, h, f, a, i, c;
} seen_tags;

/* One tag of a header line (tlen bytes from tag, its letter first) into header. */
static sh_status parse_tag(const char *name, const char *tag, size_t tlen, seen_tags *seen, sh_y4m_header *header)
{
    const char *val = tag + 1;
    size_t vlen = tlen - 1;
    int tag_len = tlen > 64 ? 64 : (int)tlen; /* bounds the tag echoed in messages */
    switch (tag[0]) {
    case 'W':
    case 'H': {
        int *once = tag[0] == 'W' ? &seen->w : &seen->h;
        int v;
        if (*once) return sh_error_set(SH_EFORMAT, "%s: Y4M header repeats %c", name, tag[0]);
        if (!parse_uint(val, vlen, &v) || v <= 0 || v > MAX_DIM)
            return sh_error_set(SH_EFORMAT, "%s: bad Y4M size tag '%.*s' (1..%d)", name,
                                tag_len, tag, MAX_DIM);
        *once = 1;
        if (tag[0] == 'W') header->width = v; else header->height = v;
        break;
    }
    case 'F':
        if (seen->f++) return sh_error_set(SH_EFORMAT, "%s: Y4M header repeats F", name);
        if (!parse_ratio(val, vlen, &header->fps_num, &header->fps_den) ||
            header->fps_num <= 0 || header->fps_den <= 0)
            return sh_error_set(SH_EFORMAT, "%s: bad Y4M frame rate '%.*s'", name, tag_len,
                                tag);
        break;
    case 'A':
        if (seen->a++) return sh_error_set(SH_EFORMAT, "%s: Y4M header repeats A", name);
        if (!parse_ratio(val, vlen, &header->aspect_num, &header->aspect_den) ||
            (header->aspect_num == 0) != (header->aspect_den == 0))
            return sh_error_set(SH_EFORMAT, "%s: bad Y4M aspect '%.*s'", name, tag_len, tag);
        break;
    case 'I':
        if (seen->i++) return sh_error_set(SH_EFORMAT, "%s: Y4M header repeats I", name);
        /* 'p','t','b','m' are the spec's; anything else ("I?") is passed through untouched. */
        if (vlen == 1 && strchr("ptbm", val[0])) {
            header->interlace = val[0];
        } else if (!append_extra(header, tag, tlen)) {
            return sh_error_set(SH_EFORMAT, "%s: Y4M extra tags exceed %d bytes", name,
                                SH_Y4M_MAX_EXTRA - 1);
        }
        break;
    case 'C':
        if (seen->c++) return sh_error_set(SH_EFORMAT, "%s: Y4M header repeats C", name);
        if (!parse_colour(val, vlen, header))
            return sh_error_set(SH_EUNSUPPORTED,
                                "%s: unsupported Y4M colour space '%.*s' (mono, 420jpeg, "
                                "420mpeg2, 420paldv and 444 are read)",
                                name, tag_len, tag);
        break;
    default: /* X tags and tags from a later spec: kept, never an error */
        if (!append_extra(header, tag, tlen))
            return sh_error_set(SH_EFORMAT, "%s: Y4M extra tags exceed %d bytes", name,
                                SH_Y4M_MAX_EXTRA - 1);
        break;
    }
    return SH_OK;
}

sh_status y4m_header_parse_named(const char *line, size_t len, const char *name,
                                 sh_y4m_header *header)
{
    if (!line || !header) return sh_error_set(SH_EINVAL, "y4m: missing argument");
    if (!name) name = "y4m";
    memset(header, 0, sizeof *header);
    header->format = SH_PIX_I420; /* no C tag means 420jpeg */
    header->siting = SH_CHROMA_CENTER;

    size_t mlen = strlen(MAGIC);
    if (len < mlen || memcmp(line, MAGIC, mlen) != 0 || (len > mlen && line[mlen] != ' '))
        return sh_error_set(SH_EFORMAT, "%s: not a YUV4MPEG2 stream (bad magic)", name);
    if (memchr(line, '\0', len))
        return sh_error_set(SH_EFORMAT, "%s: NUL byte in the Y4M header", name);

    seen_tags seen = {0, 0, 0, 0, 0, 0};
    size_t pos = mlen;
    while (pos < len) {
        if (line[pos] == ' ') { pos++; continue; } /* tolerate doubled spaces */
        size_t start = pos;
        while (pos < len && line[pos] != ' ') pos++;
        const char *tag = line + start;
        size_t tlen = pos - start;
        sh_status st = parse_tag(name, tag, tlen, &seen, header);
        if (st) return st;
    }
    if (!seen.w || !seen.h)
        return sh_error_set(SH_EFORMAT, "%s: Y4M header lacks the %s tag", name,
                            !seen.w ? "W (width)" : "H (height)");
    return SH_OK;
}

sh_status sh_y4m_header_parse(const char *line, size_t len, sh_y4m_header *header)
{
    return y4m_header_parse_named(line, len, "y4m header", header);
}

static const char *colour_tag(const sh_y4m_header *h)
{
    switch (h->format) {
    case SH_PIX_GRAY8: return "mono";
    case SH_PIX_YUV444: return "444";
    case SH_PIX_I420:
        switch (h->siting) {
        case SH_CHROMA_CENTER: return "420jpeg";
        case SH_CHROMA_LEFT: return "420mpeg2";
        case SH_CHROMA_PALDV: return "420paldv";
        }
        return NULL;
    case SH_PIX_RGB24: return NULL;
    }
    return NULL;
}

int y4m_header_format(const sh_y4m_header *h, char *out, size_t cap)
{
    const char *c = colour_tag(h);
    if (!c || h->width <= 0 || h->height <= 0 || h->width > MAX_DIM || h->height > MAX_DIM)
        return -1;
    if (memchr(h->extra, '\n', strnlen(h->extra, sizeof h->extra)) ||
        strnlen(h->extra, sizeof h->extra) == sizeof h->extra)
        return -1;
    int n = snprintf(out, cap, MAGIC " W%d H%d", h->width, h->height);
    char tag[64];
    if (h->fps_num > 0 && h->fps_den > 0) {
        snprintf(tag, sizeof tag, " F%d:%d", h->fps_num, h->fps_den);
        n += snprintf(out + n, n < (int)cap ? cap - (size_t)n : 0, "%s", tag);
    }
    if (h->interlace) {
        if (!strchr("ptbm", h->interlace)) return -1;
        n += snprintf(out + n, n < (int)cap ? cap - (size_t)n : 0, " I%c", h->interlace);
    }
    if (h->aspect_den > 0 || h->aspect_num > 0)
        n += snprintf(out + n, n < (int)cap ? cap - (size_t)n : 0, " A%d:%d", h->aspect_num,
                      h->aspect_den);
    n += snprintf(out + n, n < (int)cap ? cap - (size_t)n : 0, " C%s", c);
    if (h->extra[0]) n += snprintf(out + n, n < (int)cap ? cap - (size_t)n : 0, " %s", h->extra);
    n += snprintf(out + n, n < (int)cap ? cap - (size_t)n : 0, "\n");
    return n < (int)cap ? n : -1;
}

int sh_y4m_header_has_tag(const sh_y4m_header *h, const char *tag)
{
    size_t len = strlen(tag), n = strnlen(h->extra, sizeof h->extra);
    if (!len) return 0;
    for (size_t i = 0; i + len <= n; i++) {
        int starts = i == 0 || h->extra[i - 1] == ' ';
        int ends = i + len == n || h->extra[i + len] == ' ';
        if (starts && ends && !memcmp(h->extra + i, tag, len)) return 1;
    }
    return 0;
}

int sh_y4m_header_full_range(const sh_y4m_header *h) { return sh_y4m_header_has_tag(h, SH_Y4M_FULL_RANGE); }

/* The tag of extra (total bytes) at or after *at, its length in *len; *at moves past it. NULL
 * after the last. */
static const char *next_tag(const char *extra, size_t total, size_t *at, size_t *len)
{
    size_t i = *at;
    while (i < total && extra[i] == ' ') i++;
    size_t end = i;
    while (end < total && extra[end] != ' ') end++;
    *at = end;
    *len = end - i;
    return *len ? extra + i : NULL;
}

/* The length of the key part of the tag at t (len bytes): up to its '=' or all of it. */
static size_t tag_key_len(const char *t, size_t len)
{
    const char *eq = memchr(t, '=', len);
    return eq ? (size_t)(eq - t) : len;
}

static int tag_text_ok(const char *s)
{
    if (!*s) return 0;
    for (; *s; s++)
        if ((unsigned char)*s <= ' ' || *s == 0x7f) return 0;
    return 1;
}

sh_status sh_y4m_header_set_tag(sh_y4m_header *h, const char *key, const char *value)
{
    if (!tag_text_ok(key) || strchr(key, '=') || !tag_text_ok(value))
        return sh_error_set(SH_EINVAL, "y4m tag '%s=%s': empty, or a space or control character in it", key, value);
    char kept[SH_Y4M_MAX_EXTRA];
    size_t n = 0, klen = strlen(key), total = strnlen(h->extra, sizeof h->extra);
    size_t at = 0, len;
    const char *t;
    while ((t = next_tag(h->extra, total, &at, &len)))
        if (!(tag_key_len(t, len) == klen && !memcmp(t, key, klen))) {
            if (n) kept[n++] = ' ';
            memcpy(kept + n, t, len); /* fits: no longer than what it came from */
            n += len;
        }
    size_t need = n + (n ? 1 : 0) + klen + 1 + strlen(value);
    if (need >= sizeof h->extra)
        return sh_error_set(SH_ERANGE, "y4m tag %s: the header's tags would exceed %d bytes", key, SH_Y4M_MAX_EXTRA - 1);
    snprintf(h->extra, sizeof h->extra, "%.*s%s%s=%s", (int)n, kept, n ? " " : "", key, value);
    return SH_OK;
}

int sh_y4m_header_tag(const sh_y4m_header *h, const char *key, char *out, size_t cap)
{
    size_t klen = strlen(key), total = strnlen(h->extra, sizeof h->extra);
    size_t at = 0, len;
    const char *t;
    while ((t = next_tag(h->extra, total, &at, &len)))
        if (len > klen && t[klen] == '=' && !memcmp(t, key, klen)) {
            if (cap) snprintf(out, cap, "%.*s", (int)(len - klen - 1), t + klen + 1);
            return 1;
        }
    return 0;
}
