"""lobeview's ground floor: the contracts every layer shares (the method grammar, the cube-map
face layout, cache and asset folders). Nothing here imports another part of lobeview
(tests/test_core.py checks the import graph), so materials/ and scenes/ may use it."""
