"""onebox's library: what the commands in services/ share, split by what it is.

Nothing here parses a command line; the commands build small typed settings and call in.
"""

import os

# Render headless unless told otherwise. MuJoCo reads this when it is first imported, so it is
# set here, before anything can import mujoco.
os.environ.setdefault("MUJOCO_GL", "egl")
