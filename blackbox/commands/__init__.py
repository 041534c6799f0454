"""The commands of ``blackbox``, one module each, all of one shape.

``run(study, ...)`` does the work and returns a frozen, typed result; ``result.write(out)`` writes
its files into an existing empty folder and returns their names. The CLI checks ``--out`` before
``run`` (:func:`blackbox.commands.output.check_out`) and writes through
:func:`blackbox.commands.output.write_output`, so a result is either written whole or not at all.
Reports (Markdown and plots) live in :mod:`blackbox.reports`, one module per command.
"""
