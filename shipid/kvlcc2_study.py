"""Former location of :mod:`shipid.studies.kvlcc2` (kept so ``from shipid import kvlcc2_study`` works):
this name is the same module object."""
import sys

from .studies import kvlcc2 as _kvlcc2

sys.modules[__name__] = _kvlcc2
