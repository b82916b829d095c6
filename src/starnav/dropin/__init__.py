"""Drop-in command lines for astronomy software: ``starnav-solve-field`` and ``starnav-astap``."""
