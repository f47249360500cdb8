"""Input files and structure files: the option table and parser, .vertex/.clones/.slip readers and writers, structure generators."""
