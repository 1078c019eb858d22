"""Optional integrations with robot stacks and tools, each in its own subpackage and extra.

Nothing here is imported by ``import tagloc`` or by the CLI: a subpackage imports its framework
(``tagloc.adapters.dimos``: dimos, ``pip install 'tagloc[dimos]'``) only when it is imported.
"""
