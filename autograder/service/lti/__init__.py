"""The service as an LTI 1.3 tool (PyLTI1p3): launches, deep linking, NRPS roster, AGS scores.

:mod:`.routes` holds the routes (mounted by :func:`autograder.service.app.create_app`),
:mod:`.adapters` PyLTI1p3's FastAPI adapters, :mod:`.keys` the tool's key,
:mod:`.config` the registrations of the course file, :mod:`.accounts` LMS people
as roster entries, :mod:`.outbox` the scores on their way to the LMS, and
:mod:`.tables` their tables. See docs/lti.md.
"""
