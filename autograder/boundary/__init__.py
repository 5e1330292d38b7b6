"""The boundary: what crosses between the grader and the untrusted worker.

Plain data only: length-prefixed frames and a tagged JSON encoding of values
(numbers, arrays, strings, containers, figures, references to functions),
decoded without pickle and under size, depth and count limits. Both sides
import this room; it imports nothing of the engine, the sandbox or the service.
"""
