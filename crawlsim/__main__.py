from crawlsim.cli import main

main(prog_name="crawlsim")
