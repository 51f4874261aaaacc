"""Mutation testing of the safety-critical modules: how many small planted bugs the tests catch.

One job per module: :mod:`.mutants` makes the mutants (cosmic-ray's operators), :mod:`.finder`
finds a module's tests from what they import, :mod:`.modules` and :mod:`.equivalents` load the
configured modules and the equivalent mutants (``modules.toml``, ``equivalents.toml``),
:mod:`.runner` runs the tests against each mutant in a forked child, :mod:`.changed` picks the
modules a change touched, :mod:`.last_scores` reads and writes each module's last complete run
(``last_scores.toml``, where that module's change starts from), and :mod:`.cli` is the command
line (``run.py``; README.md).
"""
