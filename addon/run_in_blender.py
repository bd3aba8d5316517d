"""Entry point for a Blender binary: blender -b SCENE.blend --python addon/run_in_blender.py -- [options].

Puts the repository root on sys.path and runs `addon.headless` on the already opened scene with
the arguments after "--" (see `python -m addon.headless --help`). Not packaged in the extension.
"""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from addon import headless  # noqa: E402 (needs the path above)

code = headless.main(sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else [], scene_loaded=True)
if code:
    sys.exit(code)
