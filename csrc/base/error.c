#include "base/error.h"

#include <stdarg.h>
#include <stdio.h>

wenv_status wenv_error_set(wenv_error *err, wenv_status status, const char *fmt, ...)
{
    if (!err || err->status != WENV_OK)
        return err ? err->status : status;
    err->status = status;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(err->message, sizeof err->message, fmt, ap);
    va_end(ap);
    return status;
}
