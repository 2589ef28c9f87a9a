/* What each binding file adds to the module (module.c calls them in order); 0 on success, -1 with
 * an exception set.  One binding file per Python type or group of functions. */
#ifndef WENV_MODULE_H
#define WENV_MODULE_H

#include "python/convert.h"

int wenv_register_envmap(PyObject *module);     /* bind_envmap.c: Environment, load_environment */
int wenv_register_material(PyObject *module);   /* bind_material.c: Material, Lambert, CookTorrance, Tabulated */
int wenv_register_principled(PyObject *module); /* bind_principled.c: Principled */
int wenv_register_shader(PyObject *module);     /* bind_shader.c: Shader, the presets */
int wenv_register_reference(PyObject *module);  /* bind_reference.c: reference */
int wenv_register_glossmeter(PyObject *module); /* bind_glossmeter.c: Glossmeter, gloss, haze, fit_roughness */
int wenv_register_occlusion(PyObject *module);  /* bind_occlusion.c: Occluders, Occlusion */
int wenv_register_lamp(PyObject *module);       /* bind_lamp.c: Lamp */
int wenv_register_bake(PyObject *module);       /* bind_bake.c: uv_texels, extend_margin */
int wenv_register_textures(PyObject *module);   /* bind_textures.c: the procedural textures */
int wenv_register_internals(PyObject *module);  /* bind_internals.c: private hooks for the tests */

#endif
