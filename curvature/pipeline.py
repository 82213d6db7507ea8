"""Placeholder."""
FITS = ("implicit", "monge")
ORIENTATIONS = ("auto", "normals", "viewpoint")


def estimate(*args, **kwargs):
    raise NotImplementedError
