/* Measured-BRDF file readers, one file each (merl_reader.c).  Each returns an isotropic table over
 * Rusinkiewicz's angles in the layout of scene/tabulated.h, ready for wenv_tabulated_create. */
#ifndef WENV_BRDF_READERS_H
#define WENV_BRDF_READERS_H

#include <stddef.h>

#include "base/error.h"

/* MERL .binary (Matusik et al. 2003): three int32 dimensions (n_theta_h, n_theta_d, n_phi_d), then
 * 3 n doubles stored channel after channel, each channel in the order phi_d fastest, then theta_d,
 * then theta_h, scaled on reading by 1/1500, 1.15/1500 and 1.66/1500 (R, G, B).  Negative entries
 * mark samples that were not measured; they are filled from the nearest measured sample along
 * theta_d at the same (theta_h, phi_d), smaller theta_d first, and a (theta_h, phi_d) column with
 * no measured sample takes the nearest column in theta_h at the same phi_d that has one.  rgb:
 * n x 3 floats (malloc'd, the caller's), dims: the three dimensions.  WENV_ERR_IO naming the file
 * for a missing, short, truncated or over-long file, dimensions the size does not match, a NaN or
 * infinite entry or one past a float's range once scaled, or a table with no measured sample. */
wenv_status wenv_read_merl(const char *path, float **rgb, size_t dims[3], wenv_error *err);

#endif
