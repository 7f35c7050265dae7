"""Build hook for the one thing pyproject.toml cannot say without experimental keys: rul2021's verdict in C.

``hrc/temporal/_rulcore.c`` is a plain shared library (no Python headers needed), loaded with ctypes by
`hrc.temporal.rul`. It is optional: without a C compiler the install goes on and hrc uses the Python
implementation (the same verdicts, slower). After editing the C file, run ``pip install -e .`` again.
"""

from setuptools import Extension, setup

# built into hrc/temporal/_native/, a folder that is not a package, so that tools walking hrc's modules
# (tests/test_exported_members.py) do not take the library for a Python module
setup(ext_modules=[Extension("hrc.temporal._native._rulcore", ["hrc/temporal/_rulcore.c"],
                             extra_compile_args=["-O2"], optional=True)])
