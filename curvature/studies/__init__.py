"""Studies of the library, not part of it: the benchmark runners behind ``curvature bench``.

:mod:`~curvature.studies.paper` reproduces the accuracy study of Khameneifar & Feng (2019),
:mod:`~curvature.studies.accuracy` holds the default estimator to issue 6's targets,
:mod:`~curvature.studies.parts` measures the machined part shapes per region,
:mod:`~curvature.studies.jets` holds the default to CGAL's best-tuned jet fitting (issue 23);
:mod:`~curvature.studies.peers` wraps other programs' estimators (MeshLab's APSS, CGAL's jet
fitting) as references. They use the library like any caller; nothing in the library imports
them (docs/architecture.md).
"""
