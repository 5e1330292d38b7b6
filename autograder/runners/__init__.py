"""Runners: many submissions through the engine.

The batch (ids, reuse of unchanged results, the class folder's exports), the
local pool of grading slots, the Dask backend and the bundle a Dask node
unpacks. The service's queue feeds the same engine through these pieces.
"""
