"""numpydoc with its docstring template loaded once per build instead of once per docstring.

numpydoc's ``get_doc_object`` builds a Jinja environment and compiles its template on every
call (every signature and every docstring autodoc processes: about 2900 compilations for this
API reference, a third of the build's time). The extension registers numpydoc through its
own hook (``setup(app, get_doc_object_=...)``) with a function that loads the template on the
first call of a build, keeps it, and hands it to numpydoc's parser on the later calls. The
output is the same: the same template renders the same parsed docstrings.
"""

from __future__ import annotations

from typing import Any

from numpydoc import docscrape, docscrape_sphinx
from numpydoc import numpydoc as numpydoc_ext

_templates: dict[int, Any] = {}     # id(builder) -> the compiled template


def get_doc_object(obj: Any, what: str | None = None, doc: Any = None,
                   config: dict[str, Any] | None = None, builder: Any = None) -> Any:
    """numpydoc's ``get_doc_object``, reusing the template of the first call for ``builder``."""
    config = {} if config is None else config
    template = _templates.get(id(builder))
    if template is None:
        parsed = docscrape_sphinx.get_doc_object(obj, what=what, doc=doc, config=config,
                                                 builder=builder)
        _templates[id(builder)] = config["template"]
        return parsed
    config["template"] = template
    return docscrape.get_doc_object(obj, what=what, doc=doc, config=config,
                                    class_doc=docscrape_sphinx.SphinxClassDoc,
                                    func_doc=docscrape_sphinx.SphinxFunctionDoc,
                                    obj_doc=docscrape_sphinx.SphinxObjDoc)


def setup(app: Any) -> dict[str, Any]:
    """Register numpydoc with the caching ``get_doc_object``."""
    return numpydoc_ext.setup(app, get_doc_object_=get_doc_object)
