/* Placeholder until the shade bindings land. */
#include "bindings.h"

int wenv_register_shade(PyObject *module)
{
    (void)module;
    return 0;
}
