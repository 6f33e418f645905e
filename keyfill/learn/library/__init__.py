"""The motion library: real motion as the base of in-betweening (shared machinery, not a method).

* :mod:`~keyfill.learn.library.features`: pose features, ground points and headings;
* :mod:`~keyfill.learn.library.store`: build, save and load a library folder (memory-mapped, checked);
* :mod:`~keyfill.learn.library.index`: the search tree and the pose index that scores familiarity;
* :mod:`~keyfill.learn.library.search`: candidate stretches for a gap and their cost;
* :mod:`~keyfill.learn.library.stitch`: place, correct and join stretches;
* :mod:`~keyfill.learn.library.matcher`: fill every gap of a motion (the ``match`` method's work);
* :mod:`~keyfill.learn.library.guard`: per-gap familiarity for every learned human method.

docs/match.md describes the method and its figures.
"""
