"""The grading service: ``autograder serve COURSE.toml`` (needs the ``service`` extra).

Students upload notebooks and read feedback within seconds; instructors watch the
class and export grades. Modules: ``course`` (the course file), ``models``/``db``
(tables, engines, Alembic migrations), ``jobqueue`` (the queue in the database), ``workers``
(grading processes), ``intake`` (accepting uploads), ``standing`` (deadlines and
the score that counts), ``gradebook`` (exports), ``auth`` (tokens, sessions,
roster), ``app`` (the web pages and JSON API), ``server`` (start-up), ``client``
(``autograder submit``).
"""
