/* Line by line through a text in memory (core.h): the one splitter of the line-oriented parsers. */
#include "stillheart/core.h"

#include <string.h>

void sh_lines_init(sh_lines *it, const char *text, size_t len, const char *name)
{
    it->text = text;
    it->len = len;
    it->pos = 0;
    it->lineno = 0;
    it->name = name;
}

sh_status sh_lines_next(sh_lines *it, char *line, size_t cap)
{
    if (it->pos >= it->len) return SH_EEOF;
    const char *p = it->text + it->pos;
    const char *nl = memchr(p, '\n', it->len - it->pos);
    size_t n = nl ? (size_t)(nl - p) : it->len - it->pos;
    it->lineno++;
    if (n >= cap) return sh_error_set(SH_EFORMAT, "%s:%d: line too long", it->name, it->lineno);
    if (memchr(p, '\0', n)) return sh_error_set(SH_EFORMAT, "%s:%d: NUL byte", it->name, it->lineno);
    memcpy(line, p, n);
    line[n] = '\0';
    it->pos += n + 1;
    return SH_OK;
}
