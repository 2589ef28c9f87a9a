"""What the tests build their inputs and measure with, imported as `tests.helpers.<module>` (the
checkout on sys.path); the benchmarks import them from here too.

- measure.py: Blender's bundled HDRIs, random (normal, view) pairs, pairs weighted toward the
  lighting's bright reflections, relative RMSE and its control-variate estimate.
- memory.py: a setting's peak memory, measured in a fresh process (it runs itself as that child).
- merl_files.py: MERL's layout and .binary format, the specification's reading of a table in numpy,
  and analytic BRDFs to tabulate.
- cycles_sphere.py: Cycles (through bpy) rendering an unoccluded sphere, and the comparison with
  wenv.reference."""
