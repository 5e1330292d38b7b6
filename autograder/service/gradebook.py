"""Exports built from the database: grades.csv, a Canvas gradebook CSV, JUnit, Gradescope results."""

from __future__ import annotations

import csv
import io
import json
import zipfile
from typing import Sequence

from autograder.results.exports import junit_xml
from autograder.results.model import SubmissionResult
from autograder.service.course import AssignmentPolicy
from autograder.service.models import User
from autograder.service.standing import Standing


def _num(value: float | None) -> str:
    return "" if value is None else f"{value:g}"


def counted_results(rows: Sequence[tuple[User, Standing]]) -> list[SubmissionResult]:
    """The counted attempt's result of every student who has one, with the roster id as id."""
    results = []
    for user, stand in rows:
        # people's grading (released manual points, overrides) folded in, as in the score
        result = None if stand.counted is None else stand.people.result(stand.counted)
        if result is not None:
            results.append(result.__class__(**{**result.__dict__, "id": user.id}))
    return results


def grades_csv(rows: Sequence[tuple[User, Standing]]) -> str:
    """One row per roster student: raw score, late days, penalty and the score that counts."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["id", "name", "email", "attempts", "raw_score", "max_score", "late_days",
                     "penalty", "score", "outcome", "submission"])
    for user, stand in rows:
        sub = stand.counted
        writer.writerow([user.id, user.name, user.email, len(stand.attempts),
                         _num(stand.raw_score), _num(stand.max_score),
                         sub.late_days if sub else "", _num(sub.penalty if sub else None),
                         _num(stand.score), (sub.outcome if sub else
                                             ("pending" if stand.pending else "missing")),
                         sub.id if sub else ""])
    return buffer.getvalue()


def canvas_csv(policy: AssignmentPolicy, rows: Sequence[tuple[User, Standing]]) -> str:
    """Canvas's gradebook import layout: Student, ID, SIS User ID, SIS Login ID, Section, <assignment>.

    Canvas matches rows on ``ID`` (Canvas's user id, from the roster's optional
    ``canvas_id`` column) or else on ``SIS User ID`` (the roster id here), and reads
    the "Points Possible" row; students without a counted attempt get an empty cell.
    """
    max_score = next((s.max_score for _, s in rows if s.max_score is not None), None)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    column = policy.title
    writer.writerow(["Student", "ID", "SIS User ID", "SIS Login ID", "Section", column])
    writer.writerow(["Points Possible", "", "", "", "", _num(max_score)])
    for user, stand in rows:
        writer.writerow([user.name or user.id, user.canvas_id, user.id, user.email, "",
                         _num(stand.score)])
    return buffer.getvalue()


def junit(policy: AssignmentPolicy, rows: Sequence[tuple[User, Standing]]) -> str:
    return junit_xml(counted_results(rows), name=policy.name)


def gradescope_zip(rows: Sequence[tuple[User, Standing]]) -> bytes:
    """A zip of ``<roster id>/results.json`` in Gradescope's format, for the counted attempts."""
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        for result in counted_results(rows):
            archive.writestr(f"{result.id}/results.json", json.dumps(result.to_dict(), indent=1))
    return buffer.getvalue()
