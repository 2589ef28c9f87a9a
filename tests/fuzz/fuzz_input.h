/* What the fuzz targets share: each input as a file, and the check every reader's failure must pass.
 *
 * The readers take paths (and OpenEXR's C++ library, the fallback for DWAA/DWAB, opens the path
 * itself), so an input is written to an anonymous in-memory file (memfd) and named by its
 * /proc/self/fd path: no disk traffic, and nothing is left behind when the target stops. */
#ifndef WENV_FUZZ_INPUT_H
#define WENV_FUZZ_INPUT_H

#define _GNU_SOURCE /* memfd_create */

#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <unistd.h>

#include "base/error.h"

/* Writes `data` to a new in-memory file; its path goes to `path`.  Returns the descriptor, which
 * the caller closes (that frees the file).  Aborts if the system refuses: no input is tried then. */
static inline int fuzz_input_file(const uint8_t *data, size_t size, char *path, size_t path_size)
{
    int fd = memfd_create("wenv-fuzz-input", MFD_CLOEXEC);
    if (fd < 0) {
        perror("memfd_create");
        abort();
    }
    size_t done = 0;
    while (done < size) {
        ssize_t n = write(fd, data + done, size - done);
        if (n < 0 && errno == EINTR)
            continue;
        if (n <= 0) {
            perror("write to memfd");
            abort();
        }
        done += (size_t)n;
    }
    snprintf(path, path_size, "/proc/self/fd/%d", fd);
    return fd;
}

/* A reader that refuses an input must say so as the bindings expect of a bad file: WENV_ERR_IO
 * (OSError) or WENV_ERR_NOMEM, with a message naming the file.  Anything else is a bug: abort, so
 * libFuzzer keeps the input. */
static inline void fuzz_check_refusal(wenv_status status, const wenv_error *err, const char *path)
{
    if ((status != WENV_ERR_IO && status != WENV_ERR_NOMEM) || err->status != status ||
        !strstr(err->message, path)) {
        fprintf(stderr, "bad refusal: status %d, message '%s' (file %s)\n", (int)status, err->message, path);
        abort();
    }
}

#endif
