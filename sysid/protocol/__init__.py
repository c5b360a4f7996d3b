"""The paper's protocol: its tables (`paper`), the reproduction (`reproduce`), runs with
several seeds (`seed_runs`) and their statistics (`seeds`)."""
