/* libFuzzer: arbitrary bytes as $JOURNAL_STREAM, the one piece of outside input the programs' log
 * module reads (src/log/log.c: "DEV:INODE" of the stream systemd connected). Setting up the log
 * from it must neither crash nor read past the string; the level and style it was given hold. */
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "stillheart/log.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char *text = malloc(size + 1);
    if (!text) return 0;
    memcpy(text, data, size);
    text[size] = 0;
    setenv("JOURNAL_STREAM", text, 1);
    sh_log_setup(SH_LOG_DAEMON, "fuzz", SH_LOG_WARN);
    if (sh_log_get_level() != SH_LOG_WARN) abort();
    sh_log_info("filtered: never written"); /* below the level: nothing reaches libFuzzer's stderr */
    free(text);
    return 0;
}
