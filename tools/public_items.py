#!/usr/bin/env python3
"""Counts each crate's public surface: every item reachable by a public path, plus the public
inherent methods and public fields of reachable types, hidden items included (rustdoc's JSON
output, which needs a nightly toolchain):

    for p in tree-kernel tree-runtime tree-control tree-model; do
      CARGO_TARGET_DIR=target/nightly cargo +nightly rustdoc -q -p $p --lib -- \\
        -Z unstable-options --output-format json --document-hidden-items
    done
    python3 tools/public_items.py target/nightly/doc tree_kernel tree_runtime tree_control tree_model
"""
import json
import sys


def members(index, item):
    """Public inherent methods and public named fields of a struct or enum."""
    count = 0
    for kind in ("struct", "enum"):
        inner = item["inner"].get(kind)
        if inner is None:
            continue
        for impl_id in inner.get("impls", []):
            impl = index.get(str(impl_id))
            if impl and impl["inner"]["impl"].get("trait") is None:
                count += sum(
                    1
                    for m in impl["inner"]["impl"]["items"]
                    if index.get(str(m), {}).get("visibility") == "public"
                )
        fields = inner.get("kind") if kind == "struct" else None
        if isinstance(fields, dict) and "plain" in fields:
            count += sum(
                1
                for f in fields["plain"]["fields"]
                if index.get(str(f), {}).get("visibility") == "public"
            )
    return count


def main():
    doc, total = sys.argv[1], 0
    for name in sys.argv[2:]:
        with open(f"{doc}/{name}.json") as f:
            data = json.load(f)
        index, paths = data["index"], data["paths"]
        ours = {k: v for k, v in paths.items() if v["crate_id"] == 0}
        modules = sum(1 for v in ours.values() if v["kind"] == "module")
        items = [k for k, v in ours.items() if v["kind"] != "module" and k in index]
        extra = sum(members(index, index[k]) for k in items)
        total += len(items) + extra
        print(
            f"{name}: {modules} public modules, {len(items)} items with a path, "
            f"{extra} public methods and fields: {len(items) + extra}"
        )
    print("total", total)


if __name__ == "__main__":
    main()
