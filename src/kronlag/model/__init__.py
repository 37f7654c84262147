"""The model description layer: what a mechanism is, before any equation is derived.

- :mod:`.symbols`, :mod:`.inputs`: coordinates, speeds, the time ``t``; user input checked into SymPy;
- :mod:`.rotations`, :mod:`.bodies`, :mod:`.loads`, :mod:`.frames`: rotations, bodies, force
  elements and constraints, frames and body points;
- :mod:`.contributions`: what bodies and loads contribute to the equations of motion (kinetic
  energy terms, potentials, generalized forces) and the calculus the derivation lends them;
- :mod:`.joints`, :mod:`.free_bodies`: joints as named constraint rows with their reaction
  wrenches; bodies with their own coordinates;
- :mod:`.system`: :class:`~kronlag.model.system.System`, which collects all of it;
- :mod:`.expressions`, :mod:`.modelfile`: the safe reader of expression text, model files in TOML
  (:mod:`.modelfile.formats`: how body fields and loads are read and written);
- :mod:`.builtin`: the built-in models (``kronlag.models``) and the shipped model files.
"""
