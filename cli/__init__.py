"""bark's command line (installed as ``bark_cli``; the console command is ``bark``).

This package sits on top of the core: it imports click, rich and matplotlib, and ``bark`` never
imports it.
"""
