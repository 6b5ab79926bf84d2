"""Not the rfverify package: the root of a clone of its repository.

Python imports this file as ``rfverify`` only when the clone's folder is itself named
``rfverify`` and the importing script runs from the folder that contains it (the current folder
comes first on ``sys.path``, before the installed package; pytest run inside such a clone does
the same).  Without this file that import gives an empty namespace package — every
``rfverify.<name>`` an AttributeError.  Under that name this file loads the package the clone
holds, ``rfverify/`` beside it (the code an editable install of this clone runs); under any
other name it does nothing.
"""

import os as _os

if __name__ == "rfverify":
    _inner = _os.path.join(_os.path.dirname(_os.path.abspath(__file__)), "rfverify")
    __path__ = [_inner]
    __spec__.submodule_search_locations[:] = __path__
    __file__ = _os.path.join(_inner, "__init__.py")
    with open(__file__, encoding="utf-8") as _source:
        exec(compile(_source.read(), __file__, "exec"))
