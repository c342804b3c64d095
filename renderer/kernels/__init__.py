"""How the Warp kernels are built and run: which build a process loads (``cache``, with the shipped ``prebuilt/``
objects), their sample profiles (``profile``, ``profiles/``), the code-generator patch that passes big structs by
reference (``struct_refs``), native vector snippets (``vector_code``) and the CPU device's start-up and float mode
(``device``)."""
