/* Private to src/config: the key table's row (config.c), the kinds of value (value.c) and what
 * ini.c needs from config.c. */
#ifndef STILLHEART_CONFIG_INTERNAL_H
#define STILLHEART_CONFIG_INTERNAL_H

#include <stddef.h>

#include "stillheart/config.h"

/* The kinds of value (value.c). */
typedef enum { K_STR, K_BOOL, K_INT, K_DOUBLE, K_METHOD, K_IDS, K_SPEC, K_RAWFMT, K_SIZE, K_FPS, K_CTRL, K_ENUM } ktype;

typedef struct {
    const char *section, *key, *option;
    ktype type;
    sh_config_effect effect; /* when a change takes effect (config.h); never left out */
    size_t offset, size;     /* K_STR, K_METHOD, K_IDS, K_SPEC, K_RAWFMT: buffer size */
    double min, max;
    const char *help;
    const char *choices; /* K_ENUM: the names of 0, 1, ... separated by '|' */
    int cam;             /* per-camera keys: camera index + 1 */
    int alias;           /* another name of a key listed too: not written back */
} keydef; /* one row of config.c's key table */

#define WHY 256 /* a refusal's reason: room for the value it quotes, cut there */

/* Sets k from text (value.c); 0 with the reason in why (WHY bytes) when the text is refused. */
int sh_config_parse_value(sh_config *cfg, const keydef *k, const char *value, char *why);
/* k's value as sh_config_write writes it; exact 0: doubles in %g, for the reload's log. */
void sh_config_format_value(const sh_config *cfg, const keydef *k, int exact, char *out, size_t cap);

#endif
