"""The sandbox: everything that confines a process running student code.

Landlock rules and the readable paths, the seccomp filter, user, mount, IPC,
network and PID namespaces, cgroups, resource limits, the CPU clock, core
pinning, private temporary folders and the reaper that kills what a submission
left behind. The worker enters it; the grader prepares and sweeps it. This room
imports only :mod:`autograder.boundary` and :mod:`autograder.errors`.
"""
