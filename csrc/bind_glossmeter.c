/* Placeholder until the glossmeter bindings land. */
#include "bindings.h"

int wenv_register_glossmeter(PyObject *module)
{
    (void)module;
    return 0;
}
