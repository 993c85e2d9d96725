"""Checks that every key `bemcal.load` (python/bemcal/results.py) reads from summary.json is one
the JSON Schema of summary.json has (docs/reference/summary.schema.json, generated from the
types that write it), at the same place: a renamed field fails here instead of reading as empty.

Run by tests/report.rs: python check_summary_keys.py SCHEMA OUT_DIR, with the repository's
python/ on PYTHONPATH; OUT_DIR is an output folder whose summary.json has every section.
`bemcal.load(OUT_DIR)` runs with summary.json's objects recording each key asked for (present
or not); each path is then looked up in the schema. Exits non-zero, naming the paths missing.
"""

import json
import sys
from pathlib import Path

import bemcal.results as results


def wrap(value, path, seen):
    if isinstance(value, dict):
        return Recorded(value, path, seen)
    if isinstance(value, list):
        return RecordedList(value, path, seen)
    return value


class Recorded(dict):
    """A JSON object that records the path of every key read from it."""

    def __init__(self, d, path, seen):
        super().__init__(d)
        self.path, self.seen = path, seen

    def __getitem__(self, key):
        self.seen.add(self.path + (key,))
        return wrap(super().__getitem__(key), self.path + (key,), self.seen)

    def get(self, key, default=None):
        self.seen.add(self.path + (key,))
        return self[key] if key in self else default

    def items(self):
        for k, v in super().items():
            self.seen.add(self.path + ("*",))
            yield k, wrap(v, self.path + ("*",), self.seen)

    def values(self):
        return [v for _, v in self.items()]


class RecordedList(list):
    """A JSON array whose elements record as `path + ("[]",)`."""

    def __init__(self, items, path, seen):
        super().__init__(items)
        self.path, self.seen = path, seen

    def __iter__(self):
        for v in super().__iter__():
            yield wrap(v, self.path + ("[]",), self.seen)

    def __getitem__(self, i):
        return wrap(super().__getitem__(i), self.path + ("[]",), self.seen)


def alternatives(schema, defs):
    """The schemas `schema` may be: through $ref, anyOf, oneOf and allOf."""
    if "$ref" in schema:
        yield from alternatives(defs[schema["$ref"].split("/")[-1]], defs)
        return
    yield schema
    for key in ("anyOf", "oneOf", "allOf"):
        for s in schema.get(key, []):
            yield from alternatives(s, defs)


def has(schema, path, defs):
    """Whether `path` (keys, "*" for any key of a map, "[]" for an array's items) is in `schema`."""
    if not path:
        return True
    step, rest = path[0], path[1:]
    for s in alternatives(schema, defs):
        if step == "[]" and isinstance(s.get("items"), dict) and has(s["items"], rest, defs):
            return True
        if step == "*" and isinstance(s.get("additionalProperties"), dict) and has(
            s["additionalProperties"], rest, defs
        ):
            return True
        if step in s.get("properties", {}) and has(s["properties"][step], rest, defs):
            return True
    return False


schema_file, out = Path(sys.argv[1]), Path(sys.argv[2])
schema = json.loads(schema_file.read_text())
summary_text = (out / "summary.json").read_text()
seen = set()


class RecordingJson:
    """`json` as results.py sees it: summary.json's text loads as recording objects."""

    @staticmethod
    def loads(text, *args, **kwargs):
        value = json.loads(text, *args, **kwargs)
        return wrap(value, (), seen) if text == summary_text else value


results.json = RecordingJson
results.load(out)
assert seen, "bemcal.load read nothing from summary.json"
missing = sorted(".".join(p) for p in seen if not has(schema, p, schema["$defs"]))
assert not missing, f"bemcal.load reads keys summary.json's schema does not have: {missing}"
print(f"{len(seen)} paths read from summary.json, all in {schema_file.name}:")
for p in sorted(".".join(p) for p in seen):
    print(f"  {p}")
