"""REST service for the ``curvature`` library (DESIGN.md section 7).

Start it with ``python -m service``; build the app in code with
:func:`service.app.create_app`. Kept import-light: worker processes import this package too.
"""
