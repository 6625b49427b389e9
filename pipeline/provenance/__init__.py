"""What each artefact depends on, and whether a stored one is still valid (architecture §9).

Each kind of artefact has a version, a hash of exactly what makes it, and one predicate that
says whether a stored artefact of that kind may be reused. ``make``, ``run``, ``analyze``,
``claims``, ``report`` and the sweeps all ask these predicates; nothing else decides.

==========  ===============================================================================
artefact    depends on
==========  ===============================================================================
log         the simulator's sources (every ``pipeline`` module :mod:`pipeline.sim.run`
            imports, transitively, lazy imports included), the resolved spec (its hash),
            the robot file (its content hash) and the numerical libraries' versions
analysis    its log (path, spec hash, simulator version), the analysis' sources and the
            numerical libraries' versions; a comparison also its second log
sweep       its grid (base spec hash, point names), every point complete, and the
            simulator's and analysis' versions its points were made with
report      its inputs (the analysis records, claims, sweep tables, bench and baselines
            files) and the renderer's sources, templates and plotting libraries
claims      the register's content, its specs (found as an evaluation would find them) and
            robots, every source of the package, the libraries, and the bytes of every file
            its last evaluation read or wrote (logs, analyses, tables, claims.json, pages)
==========  ===============================================================================

So editing a report template re-renders the reports and nothing else, and an upgrade of NumPy
or Pinocchio re-simulates every log.
"""
