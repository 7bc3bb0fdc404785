"""railML 3.1 / 3.2 infrastructure to railcosim's line file and back (docs/railml.md), for
``railcosim new --railml`` and ``railcosim export railml``: ``read.py`` (:func:`import_railml`;
the file itself in ``document.py``, the running path through its topology in ``topology.py``,
the block sections in ``blocks.py``), ``write.py`` (:func:`export_railml`, a system's line file),
``validate.py`` (:func:`validate_railml` against the user's railML XSD), ``schema/`` (our
extension's XSD, the sidecar's JSON schema, a Dublin Core stand-in).

Data conversion on the host side only: no FMU needs railML, so this lives here, not in the
``fmus`` package every FMU bundles (docs/architecture.md).
"""
