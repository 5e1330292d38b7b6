"""axe-core (the npm package's ``axe.min.js``) run in a WebDriver page, and the layout checks
every page must pass: no WCAG 2.1 AA violation, no sideways scrolling.

``.ci/run`` installs axe-core with npm into ``build/axe`` (ignored by git); the
``NUMGRADE_AXE`` environment variable may name another ``axe.min.js``. Tests skip,
saying why, only when neither is there and npm is absent (CI has npm).
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Any

import pytest

ROOT = Path(__file__).resolve().parents[2]
#: the WCAG levels the pages must meet (axe-core's tag names)
WCAG_AA = ["wcag2a", "wcag2aa", "wcag21a", "wcag21aa"]
#: the widths every page is checked at: a small phone and a desktop
WIDTHS = (360, 1280)


def axe_script() -> str | None:
    """The text of ``axe.min.js``, or ``None`` when it is not installed."""
    for path in (os.environ.get("NUMGRADE_AXE"), ROOT / "build/axe/node_modules/axe-core/axe.min.js"):
        if path and Path(path).is_file():
            return Path(path).read_text(encoding="utf-8")
    return None


@pytest.fixture(scope="module")
def axe_js() -> str:
    """The axe-core script (a test module takes it as ``axe_js = axe.axe_js``); skipped
    with the reason when it is not installed."""
    script = axe_script()
    if script is None:
        pytest.skip(skip_reason())
    return script


def skip_reason() -> str:
    if shutil.which("npm"):
        return ("axe-core is not installed although npm is: run "
                "`npm install --prefix build/axe axe-core@4` (.ci/run does)")
    return "npm is absent, so axe-core cannot be installed (.ci/run installs it in CI)"


def violations(web: Any, script: str) -> list[str]:
    """axe-core's WCAG 2.1 AA violations of the page open in ``web``, one line each."""
    # the script goes in as the body of a WebDriver script, not through eval: the pages'
    # Content-Security-Policy forbids eval, and WebDriver's own scripts are not the page's
    web.command("POST", "/timeouts", {"script": 120_000})
    web.run(script + "\n;window.axe = axe;")
    found = web.command("POST", "/execute/async", {"script": """
        const done = arguments[arguments.length - 1];
        axe.run(document, {runOnly: {type: 'tag', values: arguments[0]}, resultTypes: ['violations']})
           .then(r => done(r.violations.map(v => v.id + ' (' + v.impact + '): ' + v.help + ' at ' +
                 v.nodes.slice(0, 3).map(n => n.target.join(' ')).join(' | '))))
           .catch(e => done(['axe failed: ' + e]));""", "args": [WCAG_AA]})
    return list(found)


def overflow(web: Any) -> dict[str, int]:
    """``scroll`` > ``inner`` means the page scrolls sideways."""
    return dict(web.run("return {scroll: document.documentElement.scrollWidth, "
                        "inner: window.innerWidth};"))


def page_problems(web: Any, script: str, url: str, *, height: int = 900) -> list[str]:
    """Every axe violation and sideways overflow of ``url`` at each of :data:`WIDTHS`."""
    problems = []
    for width in WIDTHS:
        web.resize(width, height)
        web.open(url)
        for line in violations(web, script):
            problems.append(f"{url} at {width} px: {line}")
        sizes = overflow(web)
        if sizes["scroll"] > sizes["inner"]:
            problems.append(f"{url} at {width} px: the page is {sizes['scroll']} px wide "
                            f"in a {sizes['inner']} px window")
    return problems
