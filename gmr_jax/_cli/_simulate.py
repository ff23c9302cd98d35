"""`gmr simulate` (being written)."""


def register(sub):
    p = sub.add_parser("simulate", help="(being written)")
    p.set_defaults(fn=lambda args: 0)
    return p
