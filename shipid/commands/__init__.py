"""The CLI's commands (:mod:`shipid.cli` registers them), each a thin layer over the library.

A command imports the library modules it uses inside its functions, so that ``shipid --help`` and every command
load only what they run (the identifier, the report and the solvers pull in scipy's and matplotlib's submodules,
seconds of import time).  This package is the one place where function-local imports are the rule; elsewhere
each one names its reason (an optional or heavy dependency) on its line.
"""
