"""diffsense: differentiable sensor-parameter optimisation for deep-learning perception.

Pipeline (one subpackage per stage, data flowing one way):
    scene -> sensor -> tracks -> predict -> objective -> solve
"""

from diffsense.errors import InputError

__version__ = "0.1.0"

__all__ = ["InputError", "__version__"]
