"""mkdocs hook: every object the API reference renders (``::: dotted.path``) and each of its
public methods and properties has a docstring, else a warning, which ``mkdocs build --strict``
turns into a failed build. mkdocstrings itself renders an undocumented object silently."""

from __future__ import annotations

import importlib
import inspect
import logging
import re
import sys
from pathlib import Path
from typing import Any

LOG = logging.getLogger("mkdocs.plugins.crawlsim_api_docstrings")
DIRECTIVE = re.compile(r"^:::\s+([\w.]+)\s*$", flags=re.M)


def resolve(path: str) -> Any:
    """The object at a dotted path: the longest importable module prefix, then attributes."""
    parts = path.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj: Any = importlib.import_module(".".join(parts[:cut]))
        except ImportError:
            continue
        for name in parts[cut:]:
            obj = getattr(obj, name)
        return obj
    raise ImportError(path)


def undocumented(path: str) -> list[str]:
    """``path`` and its public members (own methods and properties of a class) that have no
    docstring of their own or inherited."""
    obj = resolve(path)
    doc = (inspect.getdoc(obj) or "").strip()
    if inspect.isclass(obj) and doc.startswith(f"{obj.__name__}("):
        doc = ""  # the signature a dataclass writes for itself is no docstring
    missing = [] if doc else [path]
    if inspect.isclass(obj):
        for name, member in vars(obj).items():
            if name.startswith("_"):
                continue
            if isinstance(member, (staticmethod, classmethod)):
                member = member.__func__
            if not (inspect.isfunction(member) or isinstance(member, property)):
                continue
            doc = inspect.getdoc(getattr(obj, name)) if not isinstance(member, property) else member.__doc__
            if not (doc or "").strip():
                missing.append(f"{path}.{name}")
    return missing


def on_config(config: Any, **_: Any) -> Any:
    """Import crawlsim from this checkout (the folder of mkdocs.yml), as mkdocstrings reads it,
    not from another installed copy."""
    root = str(Path(config.config_file_path).resolve().parent)
    if root not in sys.path:
        sys.path.insert(0, root)
    for name in [m for m in sys.modules if m == "crawlsim" or m.startswith("crawlsim.")]:
        del sys.modules[name]
    return config


def on_page_markdown(markdown: str, page: Any, **_: Any) -> str:
    for path in DIRECTIVE.findall(markdown):
        for name in undocumented(path):
            LOG.warning("%s: %s has no docstring (the API reference shows it)", page.file.src_uri, name)
    return markdown
