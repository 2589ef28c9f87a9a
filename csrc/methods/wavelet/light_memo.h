/* What rays said of the exact lights' visibility, kept per vertex that holds a mask.
 *
 * Why: a light whose texels about it are partly blocked is tested by a ray, and under a lighting of
 * many small lights (a studio's softboxes) those rays were most of what shadows added to a view
 * change.  A light's visibility from a vertex does not depend on the view, so each is asked once
 * while the lighting, its frame and the scene hold.  A light is known by a 62-bit hash of its
 * direction (a narrow lobe's sub-pixel points are lights of their own), so a wrong answer needs two
 * of a vertex's lights to collide: about one chance in 10^13 for a vertex asking a thousand. */
#ifndef WENV_LIGHT_MEMO_H
#define WENV_LIGHT_MEMO_H

#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>

#include "base/error.h"

/* One vertex's answers: an open-addressing table of keys (0: empty), its answer in the low bit.  A
 * slot is written by the one thread shading its vertex. */
typedef struct {
    uint64_t *keys;
    uint32_t count, capacity;
} wenv_light_memo_slot;

typedef struct {
    wenv_light_memo_slot *slots;
    size_t n_slots;
    size_t budget;       /* bytes the tables may take together; past it, answers are not kept */
    atomic_size_t bytes; /* what they take */
} wenv_light_memo;

/* Empties the memo and sizes it for n_slots vertices. */
wenv_status wenv_light_memo_reset(wenv_light_memo *memo, size_t n_slots, size_t budget, wenv_error *err);
void wenv_light_memo_free(wenv_light_memo *memo);

/* The answer kept for unit direction l: 1 visible, 0 blocked, -1 not asked yet. */
int wenv_light_memo_find(const wenv_light_memo_slot *slot, const float l[3]);
/* Keeps the answer for l, unless the tables are at the budget. */
void wenv_light_memo_put(wenv_light_memo *memo, wenv_light_memo_slot *slot, const float l[3], int visible);

#endif
