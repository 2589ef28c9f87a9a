/* Where methods keep precomputed data on disk (wenv_method_setup's cache policy). */
#ifndef WENV_CACHE_DIR_H
#define WENV_CACHE_DIR_H

#include <stddef.h>

#include "methods/method.h"

/* The folder `setup` asks for, in buf: for WENV_CACHE_DEFAULT $WENV_CACHE_DIR, else
 * $XDG_CACHE_HOME/wenv, else ~/.cache/wenv, made with its parents if missing (*dir NULL, and no
 * error, when there is no home or it cannot be made: the method then works without a cache); for
 * WENV_CACHE_FOLDER setup->cache_dir, WENV_ERR_IO unless it is an existing folder; for
 * WENV_CACHE_NONE *dir NULL. */
wenv_status wenv_cache_dir_resolve(const wenv_method_setup *setup, char *buf, size_t size, const char **dir,
                                   wenv_error *err);

#endif
