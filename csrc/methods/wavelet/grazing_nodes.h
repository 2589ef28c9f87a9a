/* Reading the lighting at a grazing rule's nodes: the inner loop of the grazing path, written for
 * AVX-512 (gathers) and AVX2 (a 128-bit load per row of taps) with a portable version, the best for
 * the CPU chosen at run time. */
#ifndef WENV_GRAZING_NODES_H
#define WENV_GRAZING_NODES_H

#include <stddef.h>
#include <stdint.h>

#define WENV_NODE_LEVELS_MAX 16

/* The lighting as the nodes read it: an octahedral mip pyramid in one block of texels of 4 halves
 * (math/half.h), r g b and a pad, each texel's radiance over `scale`.  A bilinear tap is then one
 * 64-bit word, where float texels took three floats (or r and g as one word, and b).  Each level
 * carries a border of one texel holding its neighbour across the octahedral square's edge (the same
 * edge, mirrored), so the four taps of a read are at fixed offsets with no fold to compute: level k
 * is (side[k] + 2)^2 texels from offset[k], row after row. */
typedef struct {
    const uint16_t *texels;
    int32_t side[WENV_NODE_LEVELS_MAX], offset[WENV_NODE_LEVELS_MAX]; /* each level's side, first texel */
    int32_t top;      /* the coarsest level */
    float lod_offset; /* level = log2 of a node's footprint (radians) + this */
    float scale;      /* radiance per unit of a texel's halves (a power of two) */
    int halves_by_cpu; /* single reads convert a tap's halves with the CPU's F16C (the same floats) */
} wenv_node_pyramid;

/* The node pyramid of `levels` octahedral levels, level k `sides[k]` squared texels of r g b floats
 * at rgb[k]: into *p (all but lod_offset), its texels allocated here (the return value, which the
 * caller frees; NULL when out of memory).  The scale is a power of two that puts the largest value
 * at most 2^14: rounding cannot reach half's infinity, and half's normal range spans 2^-28 of it. */
uint16_t *wenv_node_pyramid_make(wenv_node_pyramid *p, const float *const *rgb, const size_t *sides, size_t levels);

/* The lighting in world unit direction d, read over a footprint of 2^log2_footprint radians
 * (trilinear, as the nodes read it). */
void wenv_node_pyramid_read(const wenv_node_pyramid *p, const float d[3], float log2_footprint, float rgb[3]);

/* Sum over the n nodes (a multiple of 16) of weight x lighting, the nodes being entry a and the next
 * entry b of a rule mixed g : f.  An entry holds 7 arrays of `stride` floats: local x y z, weight
 * r g b, log2 footprint.  (x, y, z) is the vertex's frame (z the normal).  Bilinear taps as
 * wenv_oct_bilinear_f, trilinear between levels. */
typedef void (*wenv_grazing_nodes_fn)(const float *a, const float *b, size_t stride, size_t n, float g, float f,
                                      const float x[3], const float y[3], const float z[3],
                                      const wenv_node_pyramid *pyramid, float rgb[3]);

/* The fastest version this CPU runs. */
wenv_grazing_nodes_fn wenv_grazing_nodes_for_cpu(void);
/* Version `which` (0 portable, 1 AVX2 (with F16C), 2 AVX-512), or NULL where this CPU or build lacks it:
 * for checking each against the portable one. */
wenv_grazing_nodes_fn wenv_grazing_nodes_version(int which);
/* The portable version, the others' reference. */
void wenv_grazing_nodes_portable(const float *a, const float *b, size_t stride, size_t n, float g, float f,
                                 const float x[3], const float y[3], const float z[3], const wenv_node_pyramid *pyramid,
                                 float rgb[3]);

#endif
