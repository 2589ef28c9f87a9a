/* The registry of shading methods behind wenv.Shader(method=...). */
#include "methods/method.h"
#include "methods/wavelet/wavelet.h"

#include <string.h>

static const wenv_method *const METHODS[] = {
    &WENV_METHOD_ROTATION,
    &WENV_METHOD_SLICING,
    &WENV_METHOD_SPLIT_SUM,
    &WENV_METHOD_SH,
};
#define N_METHODS (sizeof METHODS / sizeof METHODS[0])

size_t wenv_method_count(void) { return N_METHODS; }

const wenv_method *wenv_method_at(size_t i) { return i < N_METHODS ? METHODS[i] : NULL; }

const wenv_method *wenv_method_named(const char *name)
{
    for (size_t i = 0; name && i < N_METHODS; i++)
        if (strcmp(METHODS[i]->name, name) == 0)
            return METHODS[i];
    return NULL;
}

/* Wavelet rotation: the method this project is about, and the fastest at a given accuracy once its
 * matrices are cached (docs/performance.md, "Speed against accuracy"). */
const wenv_method *wenv_method_default(void) { return &WENV_METHOD_ROTATION; }

const wenv_method *wenv_method_choose_default(const void *quality, const wenv_method_setup *setup)
{
    return wenv_wavelet_default_method(quality, setup);
}

const void *wenv_method_preset(const wenv_method *method, const char *name)
{
    for (size_t i = 0; name && i < WENV_PRESET_COUNT; i++)
        if (strcmp(WENV_PRESET_NAMES[i], name) == 0)
            return method->presets[i];
    return NULL;
}
