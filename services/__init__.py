"""onebox's processes and tools, one module each; ``onebox --help`` lists them."""
