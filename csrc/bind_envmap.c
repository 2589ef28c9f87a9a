/* Placeholder until the envmap bindings land. */
#include "bindings.h"

int wenv_register_envmap(PyObject *module)
{
    (void)module;
    return 0;
}
