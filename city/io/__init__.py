"""Readers of users' data files: each error is one line naming the file, the row and the field."""
