"""Reading and writing what the spec (``shared/spec/session-format.md``) defines."""
