"""beyond-self: interpret and describe human actions with grounded affordances.

One import namespace for the whole distribution, so that no other package on the path (PyPI has
distributions named `runtime`, `schemas`, `services`, `cognition`, ...) and no folder of the
user's can shadow a part of it. The repository keeps its layers as top-level folders
(`cognition/`, `core/`, `runtime/`, `schemas/`, `services/`, `recordings/`); the links of the
same names in this folder place them under `beyond_self` for every tool that imports, checks or
builds the package, and a built wheel or sdist holds them as plain folders.

The version is defined here and nowhere else (pyproject.toml reads it).
"""

__version__ = "0.2.0"
