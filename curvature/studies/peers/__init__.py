"""Other programs' curvature estimators as benchmark references: MeshLab's APSS
(:mod:`~curvature.studies.peers.apss`, through pymeshlab) and CGAL's jet fitting
(:mod:`~curvature.studies.peers.cgal`, a small C++ driver compiled on first use).
"""
