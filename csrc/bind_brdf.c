/* Placeholder until the brdf bindings land. */
#include "bindings.h"

int wenv_register_brdf(PyObject *module)
{
    (void)module;
    return 0;
}
