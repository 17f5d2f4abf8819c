/* rec:DIR — replaced by the recording backend (src/record). */
#include "source_internal.h"

sh_status sh_source_open_rec(const char *dir, const sh_source_options *opts, sh_source **out)
{
    (void)opts;
    (void)out;
    return sh_error_set(SH_EUNSUPPORTED, "rec:%s: recordings not supported yet", dir);
}
