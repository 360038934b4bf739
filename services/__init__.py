"""onebox's commands, one module each: the Procfile's processes and the tools.

``onebox --help`` lists them. A command parses its flags, builds its settings and calls into the
``onebox`` library; no command imports another.
"""
