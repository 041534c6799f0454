"""The blind benchmark of ``blackbox diagnose``: random studies with a random planted effect
(``generate``), diagnosed and scored without the diagnosis ever seeing what was planted (``run``).
"""
