#include "methods/cache_dir.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/stat.h>

static int default_cache_dir(char *buf, size_t size)
{
    const char *env = getenv("WENV_CACHE_DIR");
    int n;
    if (env && env[0])
        n = snprintf(buf, size, "%s", env);
    else if ((env = getenv("XDG_CACHE_HOME")) && env[0])
        n = snprintf(buf, size, "%s/wenv", env);
    else if ((env = getenv("HOME")) && env[0])
        n = snprintf(buf, size, "%s/.cache/wenv", env);
    else
        return -1;
    if (n < 0 || (size_t)n >= size)
        return -1;
    /* the folder and its parents; a failure shows at the last mkdir */
    for (char *p = buf + 1; *p; p++) {
        if (*p == '/') {
            *p = '\0';
            mkdir(buf, 0755);
            *p = '/';
        }
    }
    if (mkdir(buf, 0755) != 0 && errno != EEXIST)
        return -1;
    return 0;
}

wenv_status wenv_cache_dir_resolve(const wenv_method_setup *setup, char *buf, size_t size, const char **dir,
                                   wenv_error *err)
{
    *dir = NULL;
    if (!setup || setup->cache == WENV_CACHE_NONE)
        return WENV_OK;
    if (setup->cache == WENV_CACHE_DEFAULT) {
        if (default_cache_dir(buf, size) == 0)
            *dir = buf;
        return WENV_OK;
    }
    struct stat sb;
    int n = setup->cache_dir ? snprintf(buf, size, "%s", setup->cache_dir) : -1;
    if (n < 0 || (size_t)n >= size || stat(buf, &sb) != 0 || !S_ISDIR(sb.st_mode))
        return wenv_error_set(err, WENV_ERR_IO, "cache_dir '%s' is not a folder",
                              setup->cache_dir ? setup->cache_dir : "(null)");
    *dir = buf;
    return WENV_OK;
}
