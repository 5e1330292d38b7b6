"""Write the problem notebooks in ``tests/files/problems/`` and their expected outcomes.

Run ``python tests/files/make_problems.py`` after editing; the outputs are
committed so the test-suite reads small files. Each notebook targets the hull
assignment (functions ``orientation`` and ``convex_hull``) and tries one way to
break, hang, or fool the grader. ``expected.toml`` says what it must get:
``score`` is the fraction of the total ("0", "1", or "partial"), ``outcome`` the
result's outcome, and ``contains`` substrings of the feedback.
"""

from __future__ import annotations

import json
from pathlib import Path

import nbformat
from nbformat.v4 import new_code_cell, new_markdown_cell, new_notebook

HERE = Path(__file__).parent / "problems"

SOLUTION = '''
from fractions import Fraction

def orientation(p, q, r):
    """+1 for a left turn, -1 for a right turn, 0 when collinear (exact)."""
    px, py, qx, qy, rx, ry = (Fraction(float(v)) for v in (*p, *q, *r))
    det = (qx - px) * (ry - py) - (qy - py) * (rx - px)
    return (det > 0) - (det < 0)

def convex_hull(points):
    pts = [tuple(map(float, p)) for p in points]
    n = len(pts)
    start = min(range(n), key=lambda i: (pts[i][0], pts[i][1], i))
    hull = [start]
    while True:
        cur = hull[-1]
        cand = None
        for j in range(n):
            if pts[j] == pts[cur]:
                continue
            if cand is None:
                cand = j
                continue
            o = orientation(pts[cur], pts[cand], pts[j])
            far = (abs(pts[j][0] - pts[cur][0]) + abs(pts[j][1] - pts[cur][1])
                   > abs(pts[cand][0] - pts[cur][0]) + abs(pts[cand][1] - pts[cur][1]))
            if o < 0 or (o == 0 and far):
                cand = j
            elif o == 0 and pts[j] == pts[cand] and j < cand:
                cand = j
        if cand is None or cand == start or len(hull) > n:
            return hull
        hull.append(cand)
'''

LIAR = '''
class Liar(int):
    def __eq__(self, other): return True
    def __ne__(self, other): return False
    __hash__ = int.__hash__

class LiarList(list):
    def __eq__(self, other): return True

import numpy as np
class LiarArray(np.ndarray):
    def __eq__(self, other): return np.ones(1, bool)

def orientation(p, q, r):
    return Liar(1)

def convex_hull(points):
    return LiarList([0, 1, 2])
'''


def nb(*sources: str, kernel: str = "python3", language: str = "python") -> nbformat.NotebookNode:
    book = new_notebook()
    book.metadata["kernelspec"] = {"name": kernel, "display_name": kernel, "language": language}
    book.metadata["language_info"] = {"name": language}
    book.cells = [new_markdown_cell("A submission used by the grader's tests.")]
    book.cells += [new_code_cell(s.strip("\n")) for s in sources]
    for number, cell in enumerate(book.cells):
        cell.id = f"cell-{number}"  # stable ids: rerunning this script changes nothing
    return book


PROBLEMS: dict[str, tuple[object, dict[str, object]]] = {
    "solution": (nb(SOLUTION), {"score": "1", "outcome": "graded"}),
    "no-code": (nb(), {"score": "0", "outcome": "graded", "contains": ["does not define"]}),
    "julia": (nb("f(x) = x^2", kernel="julia-1.9", language="julia"),
              {"score": "0", "outcome": "ungradable", "contains": ["Julia"]}),
    "magics": (nb("%matplotlib inline", "%time x = 1", "!echo hello from a shell",
                  "from IPython.display import display\ndisplay('shown')",
                  "import matplotlib.pyplot as plt\nplt.plot([0, 1], [0, 1]); plt.show()",
                  SOLUTION), {"score": "1", "outcome": "graded"}),
    "cell-raises": (nb("1 / 0", SOLUTION, "undefined_name"),
                    {"score": "1", "outcome": "graded", "cell_errors": 2}),
    "infinite-loop": (nb("while True:\n    pass", SOLUTION),
                      {"score": "1", "outcome": "timeout", "contains": ["time limit"]}),
    "loop-when-called": (nb(SOLUTION, "def convex_hull(points):\n    while True:\n        pass"),
                         {"score": "partial", "outcome": "graded", "contains": ["s of CPU time", "ran out of time on"]}),
    "exits": (nb("import sys\nsys.exit(3)", "exit()", SOLUTION), {"score": "1", "outcome": "graded"}),
    "hard-exit": (nb("import os\nos._exit(1)", SOLUTION), {"score": "1", "outcome": "crashed"}),
    "exit-when-called": (nb(SOLUTION, "import os\ndef convex_hull(points):\n    os._exit(0)"),
                         {"score": "partial", "outcome": "graded", "contains": ["ended the worker"]}),
    "kill-grader": (nb(
        "import os, signal\nme = os.getpid()\nfor pid in [os.getppid(), 1] + [int(p) for p in os.listdir('/proc') if p.isdigit() and int(p) != me]:\n"
        "    try:\n        os.kill(pid, signal.SIGKILL)\n    except OSError:\n        pass",
        "import os\ntry:\n    os.killpg(os.getpgid(os.getppid()), 9)\nexcept OSError:\n    pass",
        SOLUTION), {"score": "1", "outcome": "graded"}),
    "fork-bomb": (nb(
        "import os, time\nkids = 0\ntry:\n    while True:\n        pid = os.fork()\n        if pid == 0:\n"
        "            time.sleep(60)\n            os._exit(0)\n        kids += 1\nexcept OSError as e:\n"
        "    print('fork stopped after', kids, e)", SOLUTION),
        {"score": "1", "outcome": "graded", "escape": "processes"}),
    "memory-bomb": (nb("x = bytearray(12 * 2**30)", "import numpy as np\ny = np.ones(2**31)", SOLUTION),
                    {"score": "1", "outcome": "graded", "cell_errors": 2}),
    "flood-stdout": (nb("while True:\n    print('spam' * 1000)", SOLUTION),
                     {"score": "1", "outcome": "timeout", "max_stdout": 2_000_000}),
    "recursion": (nb("def f(n):\n    return f(n + 1)\nf(0)", SOLUTION),
                  {"score": "1", "outcome": "graded", "cell_errors": 1}),
    "deep-recursion-crash": (nb(
        "import sys\nsys.setrecursionlimit(10**8)\ndef f(n):\n    return f(n + 1) + 1\nf(0)", SOLUTION),
        {"score": "1", "contains": []}),
    "sockets": (nb(
        "import socket\nhits = []\nfor port in range(47000, 47020):\n    s = socket.socket()\n"
        "    s.settimeout(0.2)\n    try:\n        s.connect(('127.0.0.1', port))\n        s.sendall(b'escaped')\n"
        "        hits.append(port)\n    except OSError:\n        pass\n    finally:\n        s.close()\nprint('hits', hits)",
        "import socket\nsrv = socket.socket()\nsrv.bind(('127.0.0.1', 47999))\nsrv.listen()", SOLUTION),
        {"score": "1", "outcome": "graded", "escape": "network"}),
    "write-outside": (nb(
        "import os\nfor path in ['/tmp/autograder-escaped', os.path.expanduser('~/autograder-escaped'),\n"
        "             '../autograder-escaped', '/work/autograder-escaped', '/autograder-escaped']:\n"
        "    try:\n        with open(path, 'w') as fh:\n            fh.write('escaped')\n    except OSError as e:\n"
        "        print('blocked', path, type(e).__name__)", SOLUTION),
        {"score": "1", "outcome": "graded", "escape": "files"}),
    "read-tests": (nb(
        "import os, sys\nfound = []\nfor root in ['/', '/work', '/root', '/tmp', os.getcwd() + '/..']:\n"
        "    for dirpath, dirs, files in os.walk(root):\n        for f in files:\n"
        "            if 'hidden' in dirpath or f.startswith('test_'):\n"
        "                try:\n                    print(open(os.path.join(dirpath, f)).read())\n"
        "                    found.append(f)\n                except OSError:\n                    pass\n"
        "        if len(found) > 50:\n            break\nprint('found', found)", SOLUTION),
        {"score": "1", "escape": "hidden-text"}),
    "read-environ": (nb("import os\nprint(dict(os.environ))\nprint(open('/proc/1/environ').read() if os.path.exists('/proc/1/environ') else '')",
                        SOLUTION), {"score": "1", "escape": "secrets"}),
    "forged-protocol": (nb(
        "import json, os, struct\nfor fd in map(int, os.listdir('/proc/self/fd')):\n    try:\n"
        "        if 'socket' in os.readlink(f'/proc/self/fd/{fd}'):\n"
        "            fake = {'v': {'op': 'ready', 'cells': [{'bogus': 1}], 'functions': ['x']}, 'bufs': []}\n"
        "            header = json.dumps(fake).encode()\n"
        "            os.write(fd, struct.pack('>I', len(header)) + header + b'garbage' * 10)\n"
        "    except OSError:\n        pass", SOLUTION),
        {"score": "1", "outcome": "crashed"}),
    "forged-values": (nb(LIAR), {"score": "0", "outcome": "graded", "contains": ["cannot read"]}),
    "patch-numpy": (nb(
        "import numpy as np\nnp.allclose = lambda *a, **k: True\nnp.array_equal = lambda *a, **k: True\n"
        "def orientation(p, q, r):\n    return 7\ndef convex_hull(points):\n    return [-1]"),
        {"score": "0", "outcome": "graded"}),
    "forged-results": (nb(
        "import json, os\nfake = {'score': 100, 'max_score': 100, 'tests': []}\n"
        "for path in ['results.json', '../results.json', '../../results.json', '/tmp/results.json']:\n"
        "    try:\n        json.dump(fake, open(path, 'w'))\n    except OSError:\n        pass\n"
        "print('Points 100/100')\nprint(json.dumps(fake))",
        "def orientation(p, q, r):\n    return 5\ndef convex_hull(points):\n    return []"),
        {"score": "0", "outcome": "graded"}),
    "generator-result": (nb(
        "def orientation(p, q, r):\n    yield 1\ndef convex_hull(points):\n    return (i for i in range(3))"),
        {"score": "0", "outcome": "graded", "contains": ["generator"]}),
    "raises-hostile": (nb(
        "class Evil(Exception):\n    def __str__(self):\n        raise RuntimeError('no')\n"
        "def orientation(p, q, r):\n    raise Evil()\ndef convex_hull(points):\n    raise SystemExit(1)"),
        {"score": "0", "outcome": "graded"}),
    "huge-payload": (nb(SOLUTION.replace("            return hull", "            return __import__('numpy').zeros(10**8)")),
                     {"score": "partial", "outcome": "graded"}),
}

# Kernel objects and resources a submission must not keep or share (issue 9). The
# "leave" notebooks try to pass the solution on; the "take" notebooks, with no code
# of their own, look for it. Names sort so that a leaver usually runs before a taker.
IPC_KEY = 0x6E67_7261  # also in tests/autograder/test_problems.py
IPC_LEAVE = f'''
import ctypes, os
libc = ctypes.CDLL(None, use_errno=True)
code = {SOLUTION!r}.encode()
left = []
shm = libc.shmget({IPC_KEY}, 1 << 16, 0o1666)
if shm != -1:
    libc.shmat.restype = ctypes.c_void_p
    address = libc.shmat(shm, None, 0)
    if address not in (None, ctypes.c_void_p(-1).value):
        ctypes.memmove(address, code + b"\\0", len(code) + 1)
        left.append("shm")
if libc.msgget({IPC_KEY}, 0o1666) != -1:
    left.append("msg")
if libc.semget({IPC_KEY}, 1, 0o1666) != -1:
    left.append("sem")
key = libc.syscall(248, b"user\\0", b"numgrade-answers\\0", code, len(code), -4)  # add_key into the user keyring (x86-64)
if key != -1:
    left.append("keyring")
print("left behind:", left, "errno", ctypes.get_errno())
'''
IPC_TAKE = f'''
import ctypes
libc = ctypes.CDLL(None, use_errno=True)
shm = libc.shmget({IPC_KEY}, 0, 0)
if shm != -1:
    libc.shmat.restype = ctypes.c_void_p
    address = libc.shmat(shm, None, 0)
    exec(ctypes.string_at(address).decode())
    print("took the solution from System V shared memory")
serial = libc.syscall(250, 10, -4, b"user\\0", b"numgrade-answers\\0", 0)  # keyctl(KEYCTL_SEARCH), x86-64 numbers
if serial != -1 and "convex_hull" not in globals():
    buffer = ctypes.create_string_buffer(1 << 16)
    size = libc.syscall(250, 11, serial, buffer, len(buffer))  # KEYCTL_READ
    exec(buffer.raw[:size].decode())
    print("took the solution from the keyring")
'''
LISTENER_SOCKET = "/tmp/autograder-listener.sock"  # also in tests/autograder/test_problems.py
SOCKET_FAMILIES = f'''
import socket
tries = {{
    "unix-path": lambda: (socket.AF_UNIX, socket.SOCK_STREAM, 0, {LISTENER_SOCKET!r}),
    "unix-abstract": lambda: (socket.AF_UNIX, socket.SOCK_STREAM, 0, "\\0autograder-listener"),
    "unix-dgram": lambda: (socket.AF_UNIX, socket.SOCK_DGRAM, 0, {LISTENER_SOCKET!r} + ".dgram"),
    "udp": lambda: (socket.AF_INET, socket.SOCK_DGRAM, 0, ("127.0.0.1", 47000)),
    "mptcp": lambda: (socket.AF_INET, socket.SOCK_STREAM, 262, ("127.0.0.1", 47001)),
    "tcp6": lambda: (socket.AF_INET6, socket.SOCK_STREAM, 0, ("::1", 47002)),
    "ping": lambda: (socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_ICMP, ("127.0.0.1", 0)),
    "raw": lambda: (socket.AF_INET, socket.SOCK_RAW, socket.IPPROTO_ICMP, ("127.0.0.1", 0)),
    "netlink": lambda: (socket.AF_NETLINK, socket.SOCK_RAW, 0, (0, 0)),
}}
for name, spec in tries.items():
    family, kind, proto, address = spec()
    try:
        s = socket.socket(family, kind, proto)
        s.settimeout(0.5)
        s.connect(address)
        s.send(b"escaped: " + name.encode())
        print("reached", name)
    except OSError as e:
        print("blocked", name, e)
a, b = None, None
try:
    a, b = socket.socketpair()
    print("socketpair made")
except OSError as e:
    print("blocked socketpair", e)
'''
MEMFD_HOARD = '''
import os
held = []
try:
    for _ in range(16):
        fd = os.memfd_create("hoard")
        os.ftruncate(fd, 1 << 28)
        os.write(fd, b"x" * (1 << 20))
        held.append(fd)
except OSError as e:
    print("memfd refused after", len(held), e)
'''
DISK_FILL = '''
import os, signal
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
written = 0
try:
    for i in range(64):
        with open(f"fill-{i}.bin", "wb") as fh:
            for _ in range(32):
                written += fh.write(b"\\0" * (1 << 20))
except OSError as e:
    print("stopped after", written >> 20, "MiB:", e)
for name in os.listdir("."):
    if name.startswith("fill-"):
        os.remove(name)
'''
HYDRA = '''
import ctypes, os, time
def hydra():
    libc = ctypes.CDLL(None)
    while True:
        time.sleep(0.2)  # re-forks all the time, but leaves the CPU to the graded calls
        try:
            pid = os.fork()
        except OSError:
            continue
        if pid:
            os._exit(0)
        try:
            os.setsid()  # out of the process group that the grader kills
        except OSError:
            pass
        libc.prctl(15, b"ag-hydra", 0, 0, 0)  # PR_SET_NAME: the test looks for it
if os.fork() == 0:
    hydra()
'''

PROBLEMS.update({
    "ipc-a-leave": (nb(IPC_LEAVE, SOLUTION), {"score": "1", "outcome": "graded", "escape": "ipc"}),
    "ipc-b-take": (nb(IPC_TAKE), {"score": "0", "outcome": "graded", "escape": "ipc"}),
    "socket-families": (nb(SOCKET_FAMILIES, SOLUTION),
                        {"score": "1", "outcome": "graded", "escape": "network"}),
    "memfd-hoard": (nb(MEMFD_HOARD, SOLUTION), {"score": "1", "outcome": "graded"}),
    "disk-fill": (nb(DISK_FILL, SOLUTION), {"score": "1", "outcome": "graded", "escape": "files"}),
    "hydra": (nb(HYDRA, SOLUTION), {"score": "1", "outcome": "graded", "escape": "processes"}),
})

FILES = {
    "not-json.ipynb": b'{"cells": [ this is not json',
    "binary.ipynb": bytes(range(256)) * 8,
    "not-a-notebook.ipynb": b"[1, 2, 3]",
}
FILE_EXPECTED = {
    "not-json": {"score": "0", "outcome": "ungradable", "contains": ["could not be graded"]},
    "binary": {"score": "0", "outcome": "ungradable", "contains": ["could not be graded"]},
    "not-a-notebook": {"score": "0", "outcome": "ungradable", "contains": ["could not be graded"]},
    "nbformat3": {"score": "1", "outcome": "graded"},
}


def nbformat3_solution() -> dict[str, object]:
    """A real nbformat 3 notebook (worksheets), which the grader upgrades."""
    return {"nbformat": 3, "nbformat_minor": 0,
            "metadata": {"name": "", "kernelspec": {"name": "python3", "language": "python",
                                                    "display_name": "Python 3"}},
            "worksheets": [{"cells": [{"cell_type": "code", "language": "python",
                                       "input": SOLUTION.strip("\n"), "outputs": [],
                                       "collapsed": False, "metadata": {}}],
                            "metadata": {}}]}


def toml_table(name: str, values: dict[str, object]) -> str:
    lines = [f"[{name}]"]
    for key, value in values.items():
        lines.append(f"{key} = {json.dumps(value)}")
    return "\n".join(lines)


def main() -> None:
    HERE.mkdir(parents=True, exist_ok=True)
    tables = []
    for name, (book, expected) in PROBLEMS.items():
        nbformat.validate(book)
        nbformat.write(book, HERE / f"{name}.ipynb")
        tables.append(toml_table(name, expected))
    for filename, content in FILES.items():
        (HERE / filename).write_bytes(content)
    (HERE / "nbformat3.ipynb").write_text(json.dumps(nbformat3_solution(), indent=1))
    for name, expected in FILE_EXPECTED.items():
        tables.append(toml_table(name, expected))
    header = "# Written by tests/files/make_problems.py: what each problem notebook must get.\n\n"
    (HERE / "expected.toml").write_text(header + "\n\n".join(tables) + "\n")


if __name__ == "__main__":
    main()
