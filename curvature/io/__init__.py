"""File formats (placeholder until the io module lands)."""


def read(path, **kwargs):
    raise NotImplementedError


def write(path, obj, **kwargs):
    raise NotImplementedError
