"""A suspid plug-in: the strut effect ``rebound_stop`` and the model ``qcar5``."""
