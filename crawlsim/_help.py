"""``crawlsim --help`` as click renders it at the full width of 80 columns (generated: do not
edit by hand). `crawlsim.console` prints it without importing click, which alone costs more than
the interpreter's start-up; tests/test_imports.py checks that it is click's text to the byte, and
its failure message prints the text to paste here when a command or its help changes.
"""

TEXT = (
    "Usage: crawlsim [OPTIONS] COMMAND [ARGS]...\n"
    "\n"
    "  Exact simulation of soft crawlers with dry friction.\n"
    "\n"
    "  Examples:\n"
    "    crawlsim run gaits/peristalsis-4.yaml --integrator exact\n"
    "    crawlsim run gaits/inching-2.yaml --json -o inching.h5\n"
    "    crawlsim velocity gaits/peristalsis-4.yaml --sweep 'links.*.amplitude=0.1:0.4:7'\n"
    "    crawlsim info inching.h5\n"
    "    crawlsim plot inching.h5 --only motion --format pdf\n"
    "\n"
    "Options:\n"
    "  --version   Show the version and exit.\n"
    "  -h, --help  Show this message and exit.\n"
    "\n"
    "Commands:\n"
    "  animate   Animate the run in RESULTS_FILE: the blocks and links move...\n"
    "  info      Summarise a results file, of a run, a sweep or an optimisation.\n"
    "  merge     Join the shard files PART... of one sweep (written with...\n"
    "  optimize  Find the gait parameters in a box that maximise v0 (or...\n"
    "  plot      Draw the figures of RESULTS_FILE as <stem>-<figure>.<format>.\n"
    "  run       Simulate GAIT_FILE to its periodic regime; report v0 and...\n"
    "  stall     Print the load at which v0 reaches 0: the stall force...\n"
    "  validate  Check each GAIT_FILE and list every error in it, one per line...\n"
    "  velocity  Print v0 of GAIT_FILE, tabulate v0 of several, or sweep gait...\n"
    "  warmup    Compile crawlsim's kernel for every command, so that no run...\n"
    "\n"
    "  Shell completion (bash; zsh and fish alike with zsh_source, fish_source):\n"
    '    eval "$(_CRAWLSIM_COMPLETE=bash_source crawlsim)"   # in ~/.bashrc\n'
)
