"""The grading service: ``autograder serve COURSE.toml`` (needs the ``service`` extra).

Students upload notebooks and read feedback within seconds; instructors watch the
class and export grades. Modules:

- ``course`` (the course file), ``models``/``db`` (tables, engines, Alembic
  migrations), ``storage`` (uploads and result folders on disk);
- ``jobqueue`` (the queue in the database), ``settings`` (``GraderSettings``,
  what a grader process is started with, and ``LEASE_SECONDS``), ``graders``
  (the service's grader processes), ``dispatch`` (the one dispatcher process
  grading on a Dask cluster instead), ``pool`` (starting either, tied to the
  service's life);
- ``intake`` (accepting uploads), ``standing`` (deadlines and the score that
  counts), ``gradebook`` (exports), ``auth`` (tokens, sessions, roster);
- the web application: ``app`` (``create_app``, mounting the routers),
  ``web`` (what the routers share: templates, the user and course dependencies,
  CSRF, error pages), ``pages_student`` (signing in, assignments, uploads,
  feedback), ``pages_staff`` (the class, summaries, exports, regrades,
  extensions, tokens), ``api_routes`` (the JSON API of ``autograder submit``
  and the live status);
- ``server`` (start-up), ``client`` (``autograder submit``).
"""
