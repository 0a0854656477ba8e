"""The STL → MILC compiler (stages described in :mod:`twolevel.compiler.driver`)."""
