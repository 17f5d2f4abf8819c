/* What a file that is not Y4M probably is, from its first bytes, so that the refusal can say how
 * to convert it: people hand a stabilizer the MP4 their camera wrote long before they learn what
 * a Y4M file is. The signatures are the containers' own (ISO/IEC 14496-12 boxes, EBML, RIFF...). */
#include "y4m_internal.h"

#include <stdio.h>
#include <string.h>

static const char *guess(const unsigned char *b, size_t n)
{
    if (n >= 8 && !memcmp(b + 4, "ftyp", 4))
        return n >= 12 && !memcmp(b + 8, "qt  ", 4) ? "QuickTime MOV" : "MP4";
    if (n >= 8 && (!memcmp(b + 4, "moov", 4) || !memcmp(b + 4, "mdat", 4) ||
                   !memcmp(b + 4, "wide", 4) || !memcmp(b + 4, "free", 4)))
        return "QuickTime MOV";
    if (n >= 4 && !memcmp(b, "\x1a\x45\xdf\xa3", 4)) return "Matroska or WebM";
    if (n >= 12 && !memcmp(b, "RIFF", 4) && !memcmp(b + 8, "AVI ", 4)) return "AVI";
    if (n >= 8 && !memcmp(b, "\x89PNG\r\n\x1a\n", 8)) return "a PNG image";
    if (n >= 3 && !memcmp(b, "\xff\xd8\xff", 3)) return "a JPEG image";
    if (n >= 4 && !memcmp(b, "GIF8", 4)) return "a GIF image";
    if (n >= 4 && !memcmp(b, "OggS", 4)) return "Ogg";
    if (n >= 3 && !memcmp(b, "FLV", 3)) return "FLV";
    if (n >= 4 && !memcmp(b, "\0\0\1\xba", 4)) return "MPEG program stream";
    if (n >= 4 && (!memcmp(b, "\0\0\0\1", 4) || !memcmp(b, "\0\0\1", 3)))
        return "a raw H.264 or H.265 stream";
    return NULL;
}

/* Characters a shell leaves alone: anything else puts the name in single quotes. */
static int shell_plain(const char *s)
{
    for (; *s; s++)
        if (!strchr("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789._/+-,=:", *s))
            return 0;
    return 1;
}

/* name quoted for a POSIX shell into out (a ' inside becomes '\''). */
static void shell_quote(const char *name, char *out, size_t cap)
{
    size_t o = 0;
    if (shell_plain(name)) {
        snprintf(out, cap, "%s", name);
        return;
    }
    out[o++] = '\'';
    for (const char *s = name; *s && o + 6 < cap; s++) {
        if (*s == '\'') {
            memcpy(out + o, "'\\''", 4);
            o += 4;
        } else {
            out[o++] = *s;
        }
    }
    out[o++] = '\'';
    out[o] = '\0';
}

sh_status y4m_refuse_not_y4m(const unsigned char *head, size_t n, const char *name)
{
    const char *kind = guess(head, n);
    char what[64];
    if (kind) snprintf(what, sizeof what, "it looks like %s", kind);
    else snprintf(what, sizeof what, "it does not begin with the YUV4MPEG2 magic");
    if (!strcmp(name, "<stdin>"))
        return sh_error_set(SH_EFORMAT,
                            "standard input is not a Y4M video (%s); convert it: "
                            "ffmpeg -i IN -pix_fmt yuv420p -f yuv4mpegpipe - | ...", what);
    /* OUT: the input's name with .y4m for its extension (or beside it, if it had that one) */
    char in[192], stem[160], out[192];
    const char *slash = strrchr(name, '/'), *dot = strrchr(name, '.');
    if (dot && dot <= (slash ? slash + 1 : name)) dot = NULL; /* ".hidden", "dir.d/clip" */
    size_t len = dot ? (size_t)(dot - name) : strlen(name);
    snprintf(stem, sizeof stem, "%.*s", (int)(len < sizeof stem - 1 ? len : sizeof stem - 1), name);
    char conv[176];
    int same = dot && !strcmp(dot, ".y4m");
    snprintf(conv, sizeof conv, "%s%s.y4m", stem, same ? "-yuv" : "");
    shell_quote(name, in, sizeof in);
    shell_quote(conv, out, sizeof out);
    return sh_error_set(SH_EFORMAT,
                        "%s is not a Y4M video (%s); convert it: "
                        "ffmpeg -i %s -pix_fmt yuv420p -f yuv4mpegpipe %s",
                        name, what, in, out);
}
