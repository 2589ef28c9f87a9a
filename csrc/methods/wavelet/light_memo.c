/* Kept answers of the lights' rays (light_memo.h). */
#include "methods/wavelet/light_memo.h"

#include <stdlib.h>
#include <string.h>

#define FIRST_CAPACITY 16u

void wenv_light_memo_free(wenv_light_memo *memo)
{
    for (size_t i = 0; memo->slots && i < memo->n_slots; i++)
        free(memo->slots[i].keys);
    free(memo->slots);
    memo->slots = NULL;
    memo->n_slots = 0;
    atomic_store(&memo->bytes, 0);
}

wenv_status wenv_light_memo_reset(wenv_light_memo *memo, size_t n_slots, size_t budget, wenv_error *err)
{
    wenv_light_memo_free(memo);
    memo->slots = calloc(n_slots ? n_slots : 1, sizeof *memo->slots);
    if (!memo->slots)
        return wenv_error_set(err, WENV_ERR_NOMEM, "out of memory for the lights' visibility of %zu vertices", n_slots);
    memo->n_slots = n_slots;
    memo->budget = budget;
    return WENV_OK;
}

/* splitmix64's finaliser */
static inline uint64_t mix(uint64_t x)
{
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

/* The direction's key with its answer bit clear: never 0. */
static inline uint64_t key_of(const float l[3])
{
    uint32_t b[3];
    memcpy(b, l, sizeof b);
    uint64_t h = mix(mix(((uint64_t)b[0] << 32) | b[1]) ^ b[2]);
    return (h << 2) | 2u;
}

int wenv_light_memo_find(const wenv_light_memo_slot *slot, const float l[3])
{
    if (!slot->capacity)
        return -1;
    uint64_t key = key_of(l);
    uint32_t mask = slot->capacity - 1;
    for (uint32_t at = (uint32_t)(key >> 2) & mask;; at = (at + 1) & mask) {
        uint64_t k = slot->keys[at];
        if (!k)
            return -1;
        if ((k & ~(uint64_t)1) == key)
            return (int)(k & 1u);
    }
}

static void insert(uint64_t *keys, uint32_t capacity, uint64_t entry)
{
    uint32_t mask = capacity - 1, at = (uint32_t)(entry >> 2) & mask;
    while (keys[at])
        at = (at + 1) & mask;
    keys[at] = entry;
}

void wenv_light_memo_put(wenv_light_memo *memo, wenv_light_memo_slot *slot, const float l[3], int visible)
{
    /* kept at most half full, so that a search ends at an empty entry soon */
    if (2 * (slot->count + 1) > slot->capacity) {
        uint32_t grown = slot->capacity ? 2 * slot->capacity : FIRST_CAPACITY;
        size_t add = (size_t)(grown - slot->capacity) * sizeof(uint64_t);
        if (grown > (1u << 24) || atomic_fetch_add(&memo->bytes, add) + add > memo->budget)
            return; /* over the budget: the ray is cast again next time */
        uint64_t *keys = calloc(grown, sizeof *keys);
        if (!keys)
            return;
        for (uint32_t i = 0; i < slot->capacity; i++)
            if (slot->keys[i])
                insert(keys, grown, slot->keys[i]);
        free(slot->keys);
        slot->keys = keys;
        slot->capacity = grown;
    }
    insert(slot->keys, slot->capacity, key_of(l) | (visible ? 1u : 0u));
    slot->count++;
}
