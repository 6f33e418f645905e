"""The ``match`` method: in-betweens matched from a motion library (:mod:`keyfill.learn.library`)."""
