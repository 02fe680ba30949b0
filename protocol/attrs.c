/* attrs.c — attribute names (attrs.h). */
#include "attrs.h"

#include <stdio.h>

void sp_attr_names(uint32_t attrs, char *buf, size_t len)
{
    static const struct { uint32_t bit; const char *name; } names[] = {
#define SP_ATTR_ROW_(id, bit, name) {SP_ATTR_##id, name},
        SP_ATTR_LIST(SP_ATTR_ROW_)
#undef SP_ATTR_ROW_
    };
    size_t used = 0;
    if (len == 0) return;
    buf[0] = 0;
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++) {
        if (!(attrs & names[i].bit)) continue;
        int w = snprintf(buf + used, len - used, "%s%s", used ? " " : "", names[i].name);
        if (w < 0 || (size_t)w >= len - used) break;
        used += (size_t)w;
    }
}
