"""The vocabulary every layer shares and may import, depending on nothing of plantcheck:
samples and their OPC UA status codes, the identifier rule for loops and sources, and the TOML
reader that names the line of an error (configuration and scenario files)."""
