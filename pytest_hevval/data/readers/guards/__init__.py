"""Byte-level checks that refuse damaged files before a format library reads them."""
