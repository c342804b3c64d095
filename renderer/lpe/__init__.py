"""Light path expressions: the OSL grammar compiled to automata, stepped in the path tracing kernel."""
