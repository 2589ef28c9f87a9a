/* Reading the lighting at a grazing rule's nodes: the inner loop of the grazing path, written for
 * AVX-512 and AVX2 (gathers) with a portable version, the best for the CPU chosen at run time. */
#ifndef WENV_GRAZING_NODES_H
#define WENV_GRAZING_NODES_H

#include <stddef.h>
#include <stdint.h>

#define WENV_NODE_LEVELS_MAX 16

/* The lighting as the nodes read it: an octahedral mip pyramid in one block of texels of 4 floats,
 * r g b and a pad (AVX-512 reads r and g as one 64-bit word: a third fewer gathered elements). */
typedef struct {
    const float *texels;
    int32_t side[WENV_NODE_LEVELS_MAX], offset[WENV_NODE_LEVELS_MAX]; /* each level's side, first texel */
    int32_t top;      /* the coarsest level */
    float lod_offset; /* level = log2 of a node's footprint (radians) + this */
} wenv_node_pyramid;

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
/* The portable version, the others' reference. */
void wenv_grazing_nodes_portable(const float *a, const float *b, size_t stride, size_t n, float g, float f,
                                 const float x[3], const float y[3], const float z[3], const wenv_node_pyramid *pyramid,
                                 float rgb[3]);

#endif
