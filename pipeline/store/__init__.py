"""The one door to the artefacts (architecture §9): where logs, analyses, sweep tables and
reports live, whether a stored one is current, and making what is missing, once.

- :mod:`pipeline.store.door`: :class:`~pipeline.store.door.ArtefactStore`, which hands out
  verified logs and analysis records, reused when current, else made, under the folder's lock;
- :mod:`pipeline.store.validity`: one predicate per artefact kind, from the keys of
  :mod:`pipeline.provenance.keys`;
- :mod:`pipeline.store.locks`: the folder lock and the clean-up of a killed writer's files.

Each kind of artefact has a version, a hash of exactly what makes it, and one predicate that
says whether a stored artefact of that kind may be reused. ``make``, ``run``, ``analyze``,
``claims``, ``report`` and the sweeps all ask these predicates, through the door for logs and
analyses; nothing else decides (tests/test_layout.py holds it so).

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
