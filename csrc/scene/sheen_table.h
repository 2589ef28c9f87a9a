/* Cycles' Principled sheen table (scripts/measure_sheen_table.py measures it from Cycles): the linearly
 * transformed cosine's A and B and the albedo R over [sheen roughness 32][mu = n.v 32], nodes at
 * i / 31, read bilinearly as Cycles reads it. */
#ifndef WENV_SHEEN_TABLE_H
#define WENV_SHEEN_TABLE_H

extern const float wenv_sheen_ltc[3 * 32 * 32]; /* [A, B, R][roughness][mu] */

#endif
