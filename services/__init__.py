"""onebox's processes and tools, one module each; ``onebox --help`` lists them."""

import os

# Render headless unless told otherwise. MuJoCo reads this when it is first imported, so it is
# set here, before any service can import mujoco.
os.environ.setdefault("MUJOCO_GL", "egl")
