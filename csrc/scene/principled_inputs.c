/* The Principled BSDF's inputs as rows (principled_inputs.h), from the one list. */
#include "scene/principled_inputs.h"

#define WENV_PRINCIPLED_ROW(name_, n_, socket_, r, g, b, lo_, hi_, scales_, shading_, rule_, threshold_, partner_,   \
                            note_)                                                                                 \
    {.name = #name_, .socket = socket_, .offset = offsetof(wenv_principled_inputs, name_), .n = n_,                \
     .fallback = {r, g, b}, .lo = lo_, .hi = hi_, .scales = scales_, .shading = shading_, .rule = rule_,           \
     .threshold = threshold_, .partner = partner_, .note = note_},

const wenv_principled_input wenv_principled_input_list[] = {WENV_PRINCIPLED_INPUTS(WENV_PRINCIPLED_ROW)};
const size_t wenv_principled_input_count = sizeof wenv_principled_input_list / sizeof wenv_principled_input_list[0];

/* The per-vertex inputs' rows, found by name: every one is a row of the list above. */
#define WENV_VERTEX_INPUT_ROW(name_, n_)                                                                           \
    {.name = #name_, .n = n_, .row = &wenv_principled_input_list[WENV_PRINCIPLED_ROW_INDEX_##name_]},
#define WENV_PRINCIPLED_ROW_ENUM(name_, ...) WENV_PRINCIPLED_ROW_INDEX_##name_,
enum { WENV_PRINCIPLED_INPUTS(WENV_PRINCIPLED_ROW_ENUM) };

const wenv_vertex_input wenv_vertex_input_list[WENV_VERTEX_INPUT_COUNT] = {WENV_VERTEX_INPUTS(WENV_VERTEX_INPUT_ROW)};

wenv_status wenv_vertex_inputs_check(const wenv_vertex_inputs *vi, size_t n, wenv_error *err)
{
    for (int k = 0; vi && k < WENV_VERTEX_INPUT_COUNT; k++) {
        const float *v = vi->value[k];
        size_t width = (size_t)wenv_vertex_input_list[k].n;
        for (size_t j = 0; v && j < width * n; j++)
            if (!isfinite(v[j]))
                return wenv_error_set(err, WENV_ERR_VALUE, "%s[%zu] is %g: a vertex's %s must be finite",
                                      wenv_vertex_input_list[k].name, j / width, (double)v[j],
                                      wenv_vertex_input_list[k].name);
    }
    return WENV_OK;
}
