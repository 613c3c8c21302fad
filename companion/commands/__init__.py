"""The CLI's commands: one module per ``companion COMMAND`` (``register`` its parser, ``run`` it), wired by ``cli``; and the helpers they share (arguments, options, config_file, flight, run_result).
May import: every layer below (``core``, ``sim``, ``mission``, ``mav``, ``live``, ``bus``, ``security``, ``logs``, ``ident``, ``preflight``, ``profiles``, ``view``) and ``errors``, ``progress``, ``secretfile``; only ``cli`` imports it.
"""
