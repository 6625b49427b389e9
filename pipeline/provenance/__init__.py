"""What each artefact depends on (architecture §9): the versions and hashes of exactly what
makes it (:mod:`pipeline.provenance.keys`). Whether a stored artefact is current is decided
beside the one door to the artefacts, :mod:`pipeline.store`, from these keys.
"""
