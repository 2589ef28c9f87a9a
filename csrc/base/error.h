/* Status codes and messages passed from the numerical core to the Python bindings. */
#ifndef WENV_ERROR_H
#define WENV_ERROR_H

#include <stddef.h>

typedef enum {
    WENV_OK = 0,
    WENV_ERR_VALUE,     /* bad argument value -> ValueError */
    WENV_ERR_TYPE,      /* bad argument type -> TypeError */
    WENV_ERR_IO,        /* file missing, unreadable or corrupt -> OSError */
    WENV_ERR_NOMEM,     /* allocation failed -> MemoryError */
    WENV_ERR_CANCELLED  /* progress callback asked to stop -> KeyboardInterrupt-like */
} wenv_status;

typedef struct {
    wenv_status status;
    char message[512];
} wenv_error;

/* Records the first error only: later calls keep the original cause. Returns status. */
wenv_status wenv_error_set(wenv_error *err, wenv_status status, const char *fmt, ...)
    __attribute__((format(printf, 3, 4)));

#endif
