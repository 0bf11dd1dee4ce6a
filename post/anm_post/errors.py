"""Errors raised by anm_post: the message names the file (and line or option) and what is wrong."""


class AnmPostError(Exception):
    """Bad input to anm_post; the message names the file, line or option."""
