"""A plug-in that declares the effect ``ghost`` but defines no class ``Ghost``."""
