"""Helpers shared by several test modules (import as ``from helpers.<module> import ...``).

``tests/`` is on ``sys.path`` while pytest runs (rootdir-relative conftest, no ``tests/__init__.py``), so this
package imports as ``helpers``. Fixtures belong in ``tests/conftest.py``; plain functions and builders live here,
one module per concept. A test module never imports from another test module.
"""
