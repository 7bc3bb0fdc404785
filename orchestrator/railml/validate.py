"""A railML file checked against the railML XSD in a folder the user has (docs/railml.md#validation:
the railML schemas are not redistributable) and against our extension's schema, with no network:
the Dublin Core schema railML imports by its web address comes from that folder or our stand-in.
"""
from __future__ import annotations

from pathlib import Path
from typing import List, Tuple

from lxml import etree

from orchestrator.errors import UserError
from orchestrator.railml.document import DUBLIN_CORE_XSD, EXTENSION_NS, EXTENSION_XSD, VERSION_OF_NS, parse_document


class _LocalSchemas(etree.Resolver):
    """Schema imports resolved on this machine: the Dublin Core schema railML's common3.xsd names
    by its web address (from the user's folder when it holds a dc.xsd, else our stand-in), no
    network."""

    def __init__(self, folder: Path):
        super().__init__()
        self.folder = folder

    def resolve(self, url, public_id, context):
        if url and url.startswith(("http://", "https://")):
            local = self.folder / Path(url).name
            if Path(url).name == "dc.xsd" and not local.is_file():
                local = DUBLIN_CORE_XSD
            if local.is_file():
                return self.resolve_filename(str(local), context)
            raise UserError(f"--schema {self.folder}: the railML schema imports {url}, which is not in the folder "
                            "(no network is used): put a copy there")
        return None


def validate_railml(path, schema_dir) -> Tuple[bool, List[str]]:
    """``path`` against the railML XSD in ``schema_dir`` (its railml3.xsd) and our extension
    schema: (valid, every error as 'line N: message')."""
    schema_dir = Path(schema_dir)
    root_xsd = schema_dir / "railml3.xsd"
    if not root_xsd.is_file():
        raise UserError(f"--schema {schema_dir}: no railml3.xsd there (the folder of the railML 3.1 or 3.2 "
                        "schema files as railML.org distributes them)")
    doc = parse_document(Path(path))
    try:
        target = etree.parse(str(root_xsd), etree.XMLParser(resolve_entities=False, no_network=True)
                             ).getroot().get("targetNamespace")
    except etree.XMLSyntaxError as error:      # an undefined entity, a truncated file, not XML at all
        raise UserError(f"--schema {schema_dir}: {root_xsd}:{error.lineno}: not an XML document "
                        f"({error.msg})") from None
    except OSError as error:
        raise UserError(f"--schema {schema_dir}: {root_xsd}: cannot be read ({error})") from None
    if target != doc.ns:
        raise UserError(f"--schema {schema_dir}: holds the railML schema of {target}; {path} is railML "
                        f"{VERSION_OF_NS[doc.ns]} ({doc.ns})")
    driver = (f'<xs:schema xmlns:xs="http://www.w3.org/2001/XMLSchema" targetNamespace="urn:railcosim:validation">'
              f'<xs:import namespace="{doc.ns}" schemaLocation="{root_xsd.resolve().as_uri()}"/>'
              f'<xs:import namespace="{EXTENSION_NS}" schemaLocation="{EXTENSION_XSD.as_uri()}"/>'
              f'</xs:schema>')
    parser = etree.XMLParser(no_network=True)
    parser.resolvers.add(_LocalSchemas(schema_dir))
    try:
        schema = etree.XMLSchema(etree.fromstring(driver.encode(), parser, base_url=str(schema_dir.resolve()) + "/"))
    except etree.XMLSchemaParseError as error:
        # the first problem, in the file it is in (an included schema's own, not the driver's)
        entry = next((e for e in error.error_log if e.filename and not e.filename.startswith("<")), None)
        where = f"{_file_of(entry.filename)}:{entry.line}: " if entry is not None else ""
        message = entry.message if entry is not None else str(error)
        raise UserError(f"--schema {schema_dir}: {where}the schema does not load ({' '.join(message.split())})") \
            from None
    valid = schema.validate(doc.root.getroottree())
    return valid, [f"line {e.line}: {e.message}" for e in schema.error_log]


def _file_of(url: str) -> str:
    """A path for messages from the file: URL lxml names a schema file by."""
    from urllib.parse import unquote, urlparse

    return unquote(urlparse(url).path) if url.startswith("file:") else url
