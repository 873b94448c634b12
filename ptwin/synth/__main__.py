from ptwin.synth.cli import main

main()
