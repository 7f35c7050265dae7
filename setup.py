"""Build hook for the one thing pyproject.toml cannot say without experimental keys: the native core.

``hrc/temporal/_rulcore.c`` (rul2021's verdict), ``hrc/temporal/_stncore.c`` (STN shortest distances),
``hrc/compile/_patterncore.c`` (motion acquisition's search over passing orders, which calls that verdict)
and ``hrc/dispatch/_dispatchcore.c`` (the dispatcher's set ranking, which calls it too) make one plain
shared library (no Python headers needed), loaded with ctypes by `hrc.temporal.rul.native_library`. It is
optional: without a C compiler the install goes on and hrc uses the Python implementations (the same
results, slower). After editing a C file, run ``pip install -e .`` again.
"""

from setuptools import Extension, setup

# built into hrc/temporal/_native/, a folder that is not a package, so that tools walking hrc's modules
# (tests/test_exported_members.py) do not take the library for a Python module
setup(ext_modules=[Extension("hrc.temporal._native._rulcore",
                             ["hrc/temporal/_rulcore.c", "hrc/temporal/_stncore.c",
                              "hrc/compile/_patterncore.c", "hrc/dispatch/_dispatchcore.c"],
                             depends=["hrc/temporal/_rulcore.h"], extra_compile_args=["-O2"], optional=True)])
