"""BlackJAX-shaped samplers: ``init``, ``build_kernel``, ``as_top_level_api``."""
