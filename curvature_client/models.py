"""What the client hands back: a job's state and a result's arrays."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

FINAL_STATUSES = ("succeeded", "failed", "cancelled")


@dataclass(frozen=True)
class Job:
    """A job as the service last described it (``GET /v1/jobs/{id}``).

    Attributes
    ----------
    id : str
    status : {"queued", "running", "succeeded", "failed", "cancelled"}
    progress : float
        0..1.
    n_points : int or None
        Known once a worker has read the input.
    error : dict or None
        The problem document of a failed job.
    data : dict
        The whole job document (params, timestamps, result summary, links).
    """

    id: str
    status: str
    progress: float = 0.0
    n_points: int | None = None
    error: dict | None = None
    data: dict = field(default_factory=dict, repr=False, compare=False)

    @classmethod
    def from_json(cls, doc: dict) -> Job:
        return cls(id=str(doc["id"]), status=str(doc["status"]),
                   progress=float(doc.get("progress") or 0.0), n_points=doc.get("n_points"),
                   error=doc.get("error"), data=dict(doc))

    @property
    def is_final(self) -> bool:
        """Whether the job has stopped (succeeded, failed or cancelled)."""
        return self.status in FINAL_STATUSES


class RemoteResult(dict):
    """The arrays of a job's result (its NPZ), by name, also readable as attributes.

    Keys as the service writes them: ``points`` (n, 3), ``normals``, ``dir1``, ``dir2``
    (n, 3) float64; ``k1``, ``k2``, ``mean``, ``gaussian``, ``residual`` and the standard
    errors ``k1_std``, ``k2_std``, ``mean_std`` (n,) float64 with NaN where ``status != 0``;
    ``neighbor_count``, ``status``, ``uncertain`` (n,) integers; ``faces`` (m, 3) when the
    input was a mesh.
    """

    def __getattr__(self, name: str) -> np.ndarray:
        try:
            return self[name]
        except KeyError:
            raise AttributeError(f"the result has no {name!r} array; it has "
                                 f"{', '.join(sorted(self))}") from None

    @property
    def n_points(self) -> int:
        """Number of points (rows of ``points``)."""
        points = self.get("points")
        return 0 if points is None else int(points.shape[0])

    @property
    def names(self) -> list[str]:
        """The array names."""
        return list(self.keys())

    def __repr__(self) -> str:
        shapes = ", ".join(f"{k}{tuple(v.shape)}" for k, v in self.items())
        return f"RemoteResult({shapes})"


def job_id_of(job: Any) -> str:
    """The id of a :class:`Job` or of an id string."""
    if isinstance(job, Job):
        return job.id
    if isinstance(job, str) and job:
        return job
    raise TypeError(f"expected a Job or a job id string, got {type(job).__name__}")
