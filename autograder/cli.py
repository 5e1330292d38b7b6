"""Command line: arguments only. Every decision lives in :mod:`autograder.api`."""

from __future__ import annotations

import argparse
import contextlib
import gc
import os
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import autograder
from autograder.errors import AutograderError, UsageError

# Everything heavier (the API, and through it nbformat, pytest, numpy, IPython) is
# imported inside the handler that needs it, so that `--help` and `--version` start
# in a fraction of a second (tests/autograder/test_startup.py checks sys.modules).
if TYPE_CHECKING:
    from autograder.engine.grader import GradingOptions
    from autograder.engine.slot import GradingSlot
    from autograder.results.model import SubmissionResult
    from autograder.runners.jobs import DaskSpec, TLSFiles


#: ``--course``, shared by ``grade`` and ``release``
_COURSE_HELP = ("an nbgrader course root (nbgrader_config.py, source/, submitted/): the "
                "assignment is the folder source/<assignment>")


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a whole number, got {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def _positive_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a number of seconds, got {text!r}") from None
    if not value > 0:
        raise argparse.ArgumentTypeError(f"must be positive, got {value}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="autograder",
        description="Release, grade and check notebook assignments in a sandboxed worker.")
    parser.add_argument("--version", action="version", version=f"%(prog)s {autograder.__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    rel = commands.add_parser("release", help="write the student version of an assignment")
    rel.add_argument("assignment", help="a folder name under assignments/ or a path to one")
    rel.add_argument("--out", type=Path, required=True, help="folder to write the student version to")
    rel.add_argument("--course", type=Path, default=None, metavar="ROOT", help=_COURSE_HELP)
    rel.add_argument("--variants", type=Path, default=None, metavar="ROSTER.csv",
                     help="write one notebook per student of this roster, each with the "
                          "student's parameters, to OUT/<student>/")
    rel.add_argument("--server", default=None, metavar="URL",
                     help="the course's service: submit() in the released notebook sends there")

    grd = commands.add_parser("grade", help="grade submitted notebooks with every check")
    grd.add_argument("assignment", help="a folder name under assignments/ or a path to one")
    grd.add_argument("submissions", nargs="*", type=Path,
                     help="notebooks, or folders of notebooks (with --course: default ROOT/submitted)")
    grd.add_argument("--course", type=Path, default=None, metavar="ROOT", help=_COURSE_HELP)
    grd.add_argument("--out", type=Path, required=True, help="folder for results.json files and grades.csv")
    grd.add_argument("--jobs", type=_positive_int, default=None,
                     help=f"submissions graded in parallel (default: number of cores, {os.cpu_count()})")
    _timing_options(grd)
    grd.add_argument("--public-only", action="store_true",
                     help="run only the public checks (what students see with `autograder check`)")
    grd.add_argument("--no-progress", action="store_true", help="never show a progress bar")
    grd.add_argument("--junit", type=Path, default=None, metavar="FILE",
                     help="also write a JUnit XML report (one testsuite per submission) to FILE")
    grd.add_argument("--ci", action="store_true",
                     help="for CI runs: print a 'Points X/Y' line per submission (GitHub Classroom), "
                          "append a Markdown report to $GITHUB_STEP_SUMMARY when set, no progress bar; "
                          "the exit status is non-zero only when grading itself failed")
    grd.add_argument("--dask", default=None, metavar="ADDRESS",
                     help="grade on a Dask cluster: local:N (N worker processes on this machine), "
                          "tls://HOST:PORT, or tcp://127.0.0.1:PORT (needs numgrade[dask])")
    grd.add_argument("--shard", default=None, metavar="K/N",
                     help="grade only shard K of N (0 <= K < N), chosen by a hash of each id; "
                          "combine the shards' folders with `autograder merge`")
    _cluster_security_options(grd)
    _connect_timeout_option(grd, default="30")

    gsc = commands.add_parser("gradescope", help="write the autograder zip for Gradescope")
    gsc.add_argument("assignment", help="a folder name under assignments/ or a path to one")
    gsc.add_argument("--out", type=Path, required=True, help="folder to write <name>-gradescope.zip to")

    new = commands.add_parser("new", help="write a working assignment folder to start from")
    new.add_argument("name", help="the assignment's name: lower-case letters, digits, underscores")
    new.add_argument("--out", type=Path, default=None,
                     help="folder to create it in (default: ./assignments if it exists, else .)")
    new.add_argument("--title", default=None, help="the notebook's title")

    val = commands.add_parser(
        "validate", help="release an assignment, check nothing leaked, grade its examples "
                         "and fail when a score is outside its band in examples/expected.toml")
    val.add_argument("assignment", help="a folder name under assignments/ or a path to one")
    val.add_argument("--work", type=Path, default=None,
                     help="keep the release and the results here (default: a temporary folder)")
    val.add_argument("--jobs", type=_positive_int, default=None,
                     help=f"examples graded in parallel (default: number of cores, {os.cpu_count()})")
    val.add_argument("--mutants", action="store_true",
                     help="also grade mutants of the model solution and report which checks "
                          "kill them (fails below [mutants] min_kill_rate of assignment.toml)")
    val.add_argument("--max-mutants", type=_positive_int, default=None,
                     help="mutants graded (default: [mutants] max of assignment.toml, or 40)")
    val.add_argument("--out", type=Path, default=None,
                     help="with --mutants: folder for mutants.json and mutants.html "
                          "(default: ./validate-ASSIGNMENT)")
    _timing_options(val)

    chk = commands.add_parser("check", help="run the public checks on your notebook before submitting")
    chk.add_argument("notebook", type=Path, help="your notebook")
    chk.add_argument("--assignment", default=None,
                     help="assignment name or folder (default: the folder the notebook is in)")
    _timing_options(chk)
    _service_commands(commands)
    _cluster_commands(commands)
    return parser


def _cluster_commands(commands: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
    mrg = commands.add_parser("merge", help="merge the results folders of shards into one")
    mrg.add_argument("folders", nargs="+", type=Path, help="the --out folders of the shards")
    mrg.add_argument("--out", type=Path, required=True, help="the merged results folder")
    mrg.add_argument("--assignment", default=None, help="assignment name or folder (for the summary's title)")
    mrg.add_argument("--junit", type=Path, default=None, metavar="FILE",
                     help="also write a JUnit XML report of the merged results to FILE")

    wrk = commands.add_parser("worker", help="serve grading slots to a Dask scheduler (a grading node)")
    wrk.add_argument("address", help="the scheduler: tls://HOST:PORT, or tcp://127.0.0.1:PORT")
    wrk.add_argument("--slots", type=_positive_int, default=1,
                     help="gradings at a time on this machine, one process each (default: 1)")
    _cluster_security_options(wrk)


def _connect_timeout_option(parser: argparse.ArgumentParser, *, default: str) -> None:
    parser.add_argument("--dask-connect-timeout", type=_positive_float, default=None, metavar="SECONDS",
                        help="how long to keep trying to reach the --dask scheduler before giving "
                             f"up (default: {default})")


def _cluster_security_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--insecure", action="store_true",
                        help="allow a plain tcp:// scheduler on another machine (Dask's messages are "
                             "pickled: only on a network nobody else can reach)")
    parser.add_argument("--tls-ca-file", type=Path, default=None, metavar="PEM",
                        help="certificate authority for a tls:// scheduler")
    parser.add_argument("--tls-cert", type=Path, default=None, metavar="PEM",
                        help="this machine's certificate for a tls:// scheduler")
    parser.add_argument("--tls-key", type=Path, default=None, metavar="PEM",
                        help="this machine's private key (if not in --tls-cert)")


def _tls(args: argparse.Namespace) -> "TLSFiles | None":
    from autograder.runners.jobs import TLSFiles

    if args.tls_ca_file is None and args.tls_cert is None:
        if args.tls_key is not None:
            raise UsageError("--tls-key needs --tls-ca-file and --tls-cert.")
        return None
    if args.tls_ca_file is None or args.tls_cert is None:
        raise UsageError("tls:// needs both --tls-ca-file and --tls-cert (and --tls-key unless "
                         "the key is in the certificate file).")
    return TLSFiles(ca_file=args.tls_ca_file, cert=args.tls_cert, key=args.tls_key)


def _dask(args: argparse.Namespace) -> "DaskSpec | None":
    from autograder.runners.jobs import DaskSpec

    if args.dask is None:
        if args.insecure or args.tls_ca_file or args.tls_cert or args.dask_connect_timeout:
            raise UsageError("--insecure, --tls-* and --dask-connect-timeout are for --dask ADDRESS.")
        return None
    return DaskSpec(args.dask, tls=_tls(args), insecure=args.insecure,
                    connect_timeout=args.dask_connect_timeout)


def _merge(args: argparse.Namespace) -> int:
    from autograder import api

    report = api.merge(args.folders, out=args.out, assignment=args.assignment, junit=args.junit)
    print(f"Merged {len(report.results)} result(s) from {len(report.sources)} folder(s) into "
          f"{args.out}: {args.out / 'grades.csv'}, {args.out / 'summary.html'}")
    errors = [r for r in report.results if r.outcome == "error"]
    for failed in errors:
        print(f"error: the grader failed on {failed.source}: {failed.output}", file=sys.stderr)
    return 1 if errors else 0


def _worker(args: argparse.Namespace) -> int:
    from autograder import api

    print(f"autograder worker: serving {args.slots} grading slot(s) to {args.address}; "
          "Ctrl-C stops.", file=sys.stderr)
    api.run_worker(args.address, slots=args.slots, tls=_tls(args), insecure=args.insecure)
    return 0


def _service_commands(commands: "argparse._SubParsersAction[argparse.ArgumentParser]") -> None:
    srv = commands.add_parser("serve", help="run the grading service for a course (web pages, queue, graders)")
    srv.add_argument("course", type=Path, help="the course TOML file (see examples/course/course.toml)")
    srv.add_argument("--host", default="127.0.0.1", help="address to listen on (default: 127.0.0.1)")
    srv.add_argument("--port", type=_positive_int, default=8000, help="port to listen on (default: 8000)")
    srv.add_argument("--database", default=None, metavar="URL",
                     help="sqlite:///FILE or postgresql://USER@HOST/NAME (default: the course file's, "
                          "else an SQLite file in the course's data folder)")
    srv.add_argument("--jobs", type=_positive_int, default=None,
                     help=f"grading processes (default: number of cores, {os.cpu_count()})")
    srv.add_argument("--lease", type=_positive_float, default=None, metavar="SECONDS",
                     help="how long a grading claim lasts without renewal before another grader "
                          "takes the job over (default: 30)")
    srv.add_argument("--dask", default=None, metavar="ADDRESS",
                     help="grade on a Dask cluster instead of local grading processes: local:N, "
                          "tls://HOST:PORT, or tcp://127.0.0.1:PORT (needs numgrade[dask])")
    _cluster_security_options(srv)
    _connect_timeout_option(srv, default="10; the job in hand then gets an error result and "
                                         "is tried again")

    ros = commands.add_parser("roster", help="import a roster CSV (id, name, email[, role], or GitHub "
                                  "Classroom's roster) into a course")
    ros.add_argument("course", type=Path, help="the course TOML file")
    ros.add_argument("roster", type=Path, help="CSV with columns id, name, email and optionally role, or GitHub "
                     "Classroom's identifier, github_username, github_id, name (id = username)")
    ros.add_argument("--database", default=None, metavar="URL", help="as for `autograder serve`")
    ros.add_argument("--tokens", type=Path, default=None, metavar="FILE",
                     help="the tokens CSV to add the new access tokens to, keeping the tokens already "
                          "in it (default: tokens.csv in the data folder)")

    sub = commands.add_parser("submit", help="submit a notebook to a grading service and print the score")
    sub.add_argument("notebook", type=Path, help="your notebook")
    sub.add_argument("--server", required=True, help="the service's address, e.g. https://grader.example.edu")
    sub.add_argument("--token", default=os.environ.get("AUTOGRADER_TOKEN"),
                     help="your access token (default: $AUTOGRADER_TOKEN)")
    sub.add_argument("--assignment", default=None, help="assignment name (default: the notebook's name)")
    sub.add_argument("--wait", type=_positive_float, default=600.0, metavar="SECONDS",
                     help="how long to wait for the grade (default: 600)")


def _timing_options(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--timeout", type=_positive_float, default=None,
                        help="seconds the whole notebook may run (default: the assignment's)")
    parser.add_argument("--call-timeout", type=_positive_float, default=None,
                        help="seconds each call into the student's code may take (default: the assignment's)")


def _options(args: argparse.Namespace) -> GradingOptions:
    from autograder.engine.grader import GradingOptions

    return GradingOptions(notebook_timeout=args.timeout, call_timeout=args.call_timeout,
                          public_only=getattr(args, "public_only", False))


def _slot_started_early(wanted: bool) -> contextlib.AbstractContextManager[GradingSlot | None]:
    """A warm parent started before the engine's imports (see ``slot.start_early``);
    the slot's own context shuts it down at the end of the command.

    The note on missing protections follows the launch: probing the machine imports the
    sandbox's libraries, which the warm parent need not wait for.
    """
    if not wanted:
        _say_missing_protections()
        return contextlib.nullcontext()
    from autograder.engine.slot import start_early

    started = start_early()
    try:
        _say_missing_protections()
    except BaseException:
        started.shutdown()
        raise
    return started


def _grade(args: argparse.Namespace) -> int:
    with _slot_started_early(args.dask is None) as started_slot:
        from autograder import api

        quiet = args.no_progress or args.ci
        if args.dask is None and not quiet and sys.stderr.isatty():  # beside the progress bar
            print(f"autograder: starting up to {args.jobs or os.cpu_count() or 1} grading "
                  "worker(s); the first results follow once they are warm...", file=sys.stderr)
        submissions = args.submissions or ([args.course / "submitted"] if args.course else [])
        if not submissions:
            raise UsageError("Give the submissions to grade (notebooks or folders), or "
                             "--course ROOT to grade ROOT/submitted of an nbgrader course.")
        report = api.grade(api.resolve_assignment(args.assignment, course=args.course),
                           submissions, out=args.out, jobs=args.jobs,
                           options=_options(args), progress=False if quiet else None,
                           dask=_dask(args), shard=args.shard,
                           junit=args.junit, started_slot=started_slot)
    if args.ci:
        summary_file = os.environ.get("GITHUB_STEP_SUMMARY") or None
        for line in api.ci_report(report, step_summary=Path(summary_file) if summary_file else None):
            print(line)
    results = report.results
    scores = [r.score / r.max_score for r in results if r.max_score]
    mean = 100 * sum(scores) / len(scores) if scores else 0.0
    outcomes: dict[str, int] = {}
    for r in results:
        outcomes[r.outcome] = outcomes.get(r.outcome, 0) + 1
    print(f"Graded {report.graded} submission(s), reused {report.reused} unchanged result(s) "
          f"in {report.seconds:.1f} s; mean score {mean:.1f}%.")
    print("Outcomes: " + ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items())))
    if report.other_shards:
        print(f"Shard {args.shard}: {report.other_shards} submission(s) left to the other shards.")
    print(f"Results: {args.out / 'grades.csv'} ({len(report.folder)} row(s), the submissions "
          f"given) and {args.out}/<id>/results.json")
    for sub_id, source in report.conflicts:
        print(f"conflict: {source} was not graded: {args.out / sub_id} holds another file's "
              "result (see the summary)", file=sys.stderr)
    print(f"Feedback: {args.out}/<id>/feedback.html; class summary: {args.out / 'summary.html'}")
    if args.junit is not None:
        print(f"JUnit XML: {args.junit}")
    for failed in report.failed:
        print(f"error: the grader failed on {failed.source}: {failed.output}", file=sys.stderr)
    return 1 if report.failed else 0


def format_check(result: SubmissionResult) -> str:
    """The student-facing text of ``autograder check``."""
    lines = [result.output, ""]
    for test in result.tests:
        mark = "PASS" if test.status == "passed" else "FAIL"
        lines.append(f"  {mark}  {test.name:<44} {test.score:g}/{test.max_score:g}")
        if test.output:
            lines += ["        " + line for line in test.output.splitlines()[:30]]
    for err in result.cell_errors:
        lines.append(f"  cell {err.cell + 1} raised {err.ename}: {err.evalue[:200]}")
    lines += ["", f"Public checks: {result.score:g}/{result.max_score:g} points. "
              "Hidden checks run when your notebook is graded."]
    return "\n".join(lines)


def _check(args: argparse.Namespace) -> int:
    with _slot_started_early(True) as started_slot:
        from autograder import api

        result = api.check(args.notebook, assignment=args.assignment, options=_options(args),
                           started_slot=started_slot)
    print(format_check(result))
    return 0 if result.score >= result.max_score else 1


def _new(args: argparse.Namespace) -> int:
    from autograder import api

    folder = api.new(args.name, out=args.out, title=args.title)
    print(f"Wrote {folder}: edit {args.name}.ipynb, the checks and the examples, then run "
          f"`autograder validate {folder}`.")
    return 0


def _validate(args: argparse.Namespace) -> int:
    with _slot_started_early(True) as started_slot:
        from autograder import api
        from autograder.authoring.validate import format_report

        report = api.validate(args.assignment, work=args.work, jobs=args.jobs,
                              options=_options(args), started_slot=started_slot,
                              mutants=args.mutants, max_mutants=args.max_mutants)
    print(format_report(report))
    if report.mutation is not None:
        from autograder.authoring.mutants_report import write_mutants

        out = args.out or Path(f"validate-{report.assignment}")
        json_path, html_path = write_mutants(report.mutation, out)
        print(f"Wrote {json_path} and {html_path}.")
    return 0 if report.ok else 1


def _release(args: argparse.Namespace) -> int:
    from autograder import api

    path = api.release(api.resolve_assignment(args.assignment, course=args.course), out=args.out,
                       variants=args.variants, server=args.server)
    if args.variants is not None:
        print(f"Wrote one student version per student of {args.variants} under {args.out}.")
        return 0
    print(f"Wrote the student version to {path.parent} (notebook: {path.name}).")
    return 0


def _gradescope(args: argparse.Namespace) -> int:
    from autograder import api

    path = api.gradescope(args.assignment, out=args.out)
    print(f"Wrote {path}: upload it as the autograder in the Gradescope assignment's settings.")
    return 0


def _serve(args: argparse.Namespace) -> int:
    from autograder.service.server import serve

    serve(args.course, host=args.host, port=args.port, database=args.database, jobs=args.jobs,
          lease_seconds=args.lease, dask=_dask(args))
    return 0


def _roster(args: argparse.Namespace) -> int:
    from autograder.service.server import import_roster, open_course

    course = open_course(args.course, database=args.database)
    done = import_roster(course, args.roster, tokens_out=args.tokens)
    print(f"Imported {len(done.added) + len(done.already)} people into {course.name}.")
    print(f"Added ({len(done.added)}): {_names(done.added)}.")
    print(f"Already there, name, email and role updated, token kept ({len(done.already)}): "
          f"{_names(done.already)}.")
    print(f"New access tokens: {done.new_tokens}, added to {done.tokens} beside the "
          f"{done.kept_tokens} already there (send each person theirs; the database keeps only "
          "hashes)." if done.tokens else "Everyone already had a token; none were made.")
    if done.unlinked:
        print(f"Not imported, no GitHub account linked in Classroom yet ({len(done.unlinked)}): "
              f"{_names(done.unlinked)}; import the roster again once they have accepted.")
    return 0


def _names(ids: tuple[str, ...], most: int = 30) -> str:
    if not ids:
        return "nobody"
    shown = ", ".join(ids[:most])
    return shown if len(ids) <= most else f"{shown} and {len(ids) - most} more"


def _submit(args: argparse.Namespace) -> int:
    from autograder.service.client import describe, submit

    result = submit(args.notebook, server=args.server, token=args.token or "",
                    assignment=args.assignment, wait=args.wait)
    print(describe(result))
    return 0 if result.status == "graded" else 1


def _say_missing_protections() -> None:
    """Say once, before grading, which protections this machine cannot give."""
    from autograder.sandbox import support

    for note in support.probe_support().notes:
        print(f"autograder: note: {note}", file=sys.stderr)


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    handlers = {"release": _release, "grade": _grade, "check": _check, "gradescope": _gradescope,
                "new": _new, "validate": _validate,
                "serve": _serve, "roster": _roster, "submit": _submit,
                "merge": _merge, "worker": _worker}
    if args.command in ("serve", "worker"):  # grade, check and validate: see _slot_started_early
        _say_missing_protections()
    try:
        return handlers[args.command](args)
    except UsageError as exc:
        print(f"autograder {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except AutograderError as exc:
        print(f"autograder {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("autograder: interrupted; results written so far are kept, run again to resume.",
              file=sys.stderr)
        return 130


def run() -> None:
    """The ``autograder`` command (and ``python -m autograder``): :func:`main`, then exit.

    Before the interpreter ends, every object it holds (pytest's session, the modules
    of numpy, scipy and the engine) moves out of the cyclic collector's reach
    (``gc.freeze``): the collections of the interpreter's own shutdown then skip them,
    which took 0.15-0.2 s at the end of each command (``autograder grade`` on one
    core: 0.17-0.30 s from the end of ``main`` to the end of the process, 0.07-0.09 s
    with the freeze). Module teardown, ``atexit`` handlers and reference-counted
    finalizers still run; nothing of the engine waits for a cycle to be collected at
    exit (slots, pools and files are closed by ``main`` itself). :func:`main` leaves
    the process as it found it, for callers that run it in theirs.
    """
    code = main()
    gc.freeze()
    sys.exit(code)


if __name__ == "__main__":
    run()
