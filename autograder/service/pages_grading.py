"""The manual grading pages: one question's answers across the class, a rubric, releases.

Teaching assistants and instructors grade. The answers of a question are those
of every student's counted attempt, in submission order and anonymous
("Submission 7 of 30") unless staff ask for names (``?names=1``). Clicking a
rubric item applies it to the answer shown (or takes it off); an item's points
can be edited later and every answer it was applied to follows. Nothing of it
reaches a student until staff release the question, or the whole assignment.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import RedirectResponse, Response
from sqlalchemy.orm import Session, sessionmaker
from starlette.concurrency import run_in_threadpool

from autograder.service import rubrics
from autograder.service.answers import read_answer
from autograder.service.course import AssignmentPolicy
from autograder.service.manual_models import AnswerGrade, RubricItem
from autograder.service.models import Submission, User
from autograder.service.standing import class_standings
from autograder.service.web import Assignment, Service, ServiceState, StaffMember, Who, check_csrf

router = APIRouter()
MAX_TEXT = 4000


@dataclass(frozen=True)
class Question:
    """A manually graded question of an assignment and how far its grading is."""

    name: str
    points: float
    graded: int
    total: int
    released: bool


def _answers(session: Session, svc: Service, policy: AssignmentPolicy
             ) -> list[tuple[User, Submission]]:
    """Each student's counted attempt, in submission order (the grading order)."""
    rows = [(u, s.counted) for u, s in class_standings(session, svc.course, policy)
            if s.counted is not None]
    return sorted(rows, key=lambda r: r[1].id)


def _manual_checks(sub: Submission) -> dict[str, float]:
    """The manually graded questions of an attempt's result, with their points."""
    tests = json.loads(sub.result_json or "{}").get("tests", [])
    return {t["name"]: float(t["max_score"]) for t in tests
            if t.get("extra_data", {}).get("kind") == "needs-person"}


def questions(session: Session, svc: Service, policy: AssignmentPolicy) -> list[Question]:
    answers = _answers(session, svc, policy)
    found: dict[str, float] = {}
    for _, sub in answers:
        for name, points in _manual_checks(sub).items():
            found.setdefault(name, points)
    people = rubrics.load(session, [s for _, s in answers])
    return [Question(name, points,
                     sum(1 for _, s in answers if (s.id, name) in people.marks),
                     sum(1 for _, s in answers if name in _manual_checks(s)),
                     people.is_released(policy.name, name)) for name, points in found.items()]


def _find_question(session: Session, svc: Service, policy: AssignmentPolicy, name: str) -> Question:
    found = next((q for q in questions(session, svc, policy) if q.name == name), None)
    if found is None:
        raise HTTPException(404, f"{policy.name} has no manually graded question {name!r} in "
                                 "any graded attempt.")
    return found


@router.get("/instructor/{name}/grading")
def grading_home(who: StaffMember, policy: Assignment, svc: ServiceState) -> Response:
    with svc.factory() as session:
        found = questions(session, svc, policy)
    return svc.page("grading_home.html.j2", who, policy=policy, questions=found)


def _answer_context(session: Session, svc: Service, policy: AssignmentPolicy, question: str,
                    number: int) -> dict[str, Any]:
    q = _find_question(session, svc, policy, question)
    answers = [(u, s) for u, s in _answers(session, svc, policy) if question in _manual_checks(s)]
    if not 1 <= number <= len(answers):
        raise HTTPException(404, f"There are {len(answers)} answers to {question!r}; "
                                 f"ask for one from 1 to {len(answers)}.")
    user, sub = answers[number - 1]
    mark = rubrics.marks_for(session, [sub.id]).get((sub.id, question))
    grade = session.get(AnswerGrade, (sub.id, question))
    return {"policy": policy, "q": q, "number": number, "count": len(answers), "user": user,
            "sub": sub, "answer": read_answer(svc.storage.upload_path(sub.sha256), question),
            "items": rubrics.items(session, policy.name, question),
            "applied": rubrics.applied_ids(session, sub.id), "mark": mark,
            "points": None if mark is None else rubrics.clamp_points(mark, q.points),
            "comment": grade.comment if grade else ""}


@router.get("/instructor/{name}/grading/{question}")
def grade_answer(question: str, who: StaffMember, policy: Assignment, svc: ServiceState,
                 n: int = 1, names: int = 0) -> Response:
    with svc.factory() as session:
        context = _answer_context(session, svc, policy, question, n)
    return svc.page("grading.html.j2", who, names=bool(names), **context)


# -- changing ----------------------------------------------------------------------------

def _text(form: Any, key: str, *, required: bool, what: str) -> str:
    value = str(form.get(key, "")).strip()
    if required and not value:
        raise HTTPException(400, f"Write {what}; it was empty.")
    if len(value) > MAX_TEXT:
        raise HTTPException(400, f"{what.capitalize()} is at most {MAX_TEXT} characters; "
                                 f"got {len(value)}.")
    return value


def _points(form: Any) -> float:
    text = str(form.get("points", "")).strip()
    try:
        value = float(text)
    except ValueError:
        raise HTTPException(400, f"Points must be a number such as 2 or -0.5; got {text!r}.")
    if value != value or abs(value) > 1e6:
        raise HTTPException(400, f"Points must be a finite number of at most 1e6; got {text!r}.")
    return value


def _back(policy: AssignmentPolicy, question: str, form: Any) -> str:
    number = str(form.get("n", "1"))
    names = "&names=1" if form.get("names") == "1" else ""
    return f"/instructor/{policy.name}/grading/{question}?n={int(number) if number.isdigit() else 1}{names}"


def _graded_sub(session: Session, svc: Service, policy: AssignmentPolicy, question: str,
                sub_id: int) -> Submission:
    """An attempt now counted for a student, with ``question`` in its result, else 404."""
    _find_question(session, svc, policy, question)
    sub = next((s for _, s in _answers(session, svc, policy) if s.id == sub_id), None)
    if sub is None or question not in _manual_checks(sub):
        raise HTTPException(404, "That attempt is not one to grade for this question (it is "
                                 "not a student's counted attempt any more); reload the page.")
    return sub


def _item(session: Session, policy: AssignmentPolicy, question: str, item_id: int) -> RubricItem:
    item = session.get(RubricItem, item_id)
    if item is None or item.assignment != policy.name or item.question != question:
        raise HTTPException(404, "There is no such rubric item for this question.")
    return item


async def small_form(request: Request, who: Who) -> Any:
    """A short form (no files), after its CSRF check."""
    form = await request.form(max_files=0, max_fields=10, max_part_size=16 * 1024)
    check_csrf(who, form, request)
    return form


@router.post("/instructor/{name}/grading/{question}/items")
async def add_item(request: Request, question: str, who: StaffMember, policy: Assignment,
                   svc: ServiceState) -> Response:
    form = await small_form(request, who)
    text, points = _text(form, "text", required=True, what="the item's text"), _points(form)

    def add(factory: sessionmaker[Session]) -> None:
        with factory.begin() as session:
            _find_question(session, svc, policy, question)
            session.add(RubricItem(assignment=policy.name, question=question, text=text,
                                   points=points))
    await run_in_threadpool(add, svc.factory)
    return RedirectResponse(_back(policy, question, form), status_code=303)


@router.post("/instructor/{name}/grading/{question}/items/{item_id}")
async def edit_item(request: Request, question: str, item_id: int, who: StaffMember,
                    policy: Assignment, svc: ServiceState) -> Response:
    form = await small_form(request, who)
    text, points = _text(form, "text", required=True, what="the item's text"), _points(form)

    def edit(factory: sessionmaker[Session]) -> None:
        with factory.begin() as session:
            item = _item(session, policy, question, item_id)
            item.text, item.points = text, points
    await run_in_threadpool(edit, svc.factory)
    return RedirectResponse(_back(policy, question, form), status_code=303)


@router.post("/instructor/{name}/grading/{question}/{sub_id}/apply/{item_id}")
async def apply_item(request: Request, question: str, sub_id: int, item_id: int,
                     who: StaffMember, policy: Assignment, svc: ServiceState) -> Response:
    form = await small_form(request, who)

    def toggle(factory: sessionmaker[Session]) -> None:
        with factory.begin() as session:
            item = _item(session, policy, question, item_id)
            rubrics.toggle_item(session, _graded_sub(session, svc, policy, question, sub_id),
                                item, who.id)
    await run_in_threadpool(toggle, svc.factory)
    return RedirectResponse(_back(policy, question, form), status_code=303)


@router.post("/instructor/{name}/grading/{question}/{sub_id}/comment")
async def comment(request: Request, question: str, sub_id: int, who: StaffMember,
                  policy: Assignment, svc: ServiceState) -> Response:
    form = await small_form(request, who)
    text = _text(form, "comment", required=False, what="the comment")

    def save(factory: sessionmaker[Session]) -> None:
        with factory.begin() as session:
            sub = _graded_sub(session, svc, policy, question, sub_id)
            rubrics.grade_row(session, sub.id, question, who.id).comment = text
    await run_in_threadpool(save, svc.factory)
    return RedirectResponse(_back(policy, question, form), status_code=303)


@router.post("/instructor/{name}/grading/release")
async def release(request: Request, who: StaffMember, policy: Assignment,
                  svc: ServiceState) -> Response:
    form = await small_form(request, who)
    question = str(form.get("question", ""))

    def save(factory: sessionmaker[Session]) -> None:
        with factory.begin() as session:
            if question:
                _find_question(session, svc, policy, question)
            rubrics.release(session, policy.name, question, who.id)
    await run_in_threadpool(save, svc.factory)
    return RedirectResponse(f"/instructor/{policy.name}/grading", status_code=303)


__all__ = ["Question", "questions", "router", "small_form"]
