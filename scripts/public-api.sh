#!/usr/bin/env bash
# The engine's public API, as rustdoc shows it, against its committed listing
# (engine/public-api.txt): every item with its declaration, its inherent
# methods and the traits it implements by name. A change of the face must be
# a reviewed diff of that file: `scripts/public-api.sh --bless` rewrites it.
# The docs are built here alone (the engine's default features), so that
# other crates' features do not change the listing.
set -euo pipefail
cd "$(dirname "$0")/.."
docs=target/doc/strata_engine
cargo doc -q --no-deps -p strata-engine
listing=$(python3 - "$docs" <<'PY'
import html, re, sys
docs = sys.argv[1]

def text(fragment):
    # A declaration of many fields is folded behind a "Show N fields" summary.
    fragment = re.sub(r"<summary[^>]*>.*?</summary>", "", fragment, flags=re.S)
    return html.unescape(re.sub(r"<[^>]+>", "", fragment)).strip()

def between(page, start, ends):
    i = page.find(start)
    if i < 0:
        return ""
    j = min([k for k in (page.find(e, i) for e in ends) if k > 0], default=len(page))
    return page[i:j]

everything = open(f"{docs}/all.html").read()
items = re.findall(r'<li><a href="([^"]+)">([^<]+)</a></li>', everything)
print(f"# strata-engine: {len(items)} public items")
for href, name in sorted(items, key=lambda item: item[1]):
    page = open(f"{docs}/{href}").read()
    decl = re.search(r'<pre class="rust item-decl"><code>(.*?)</code></pre>', page, re.S)
    print(f"\n## {name}")
    if decl:
        print(text(decl.group(1)))
    inherent = between(page, 'id="implementations-list"',
                       ['id="trait-implementations', 'id="synthetic-implementations',
                        'id="blanket-implementations'])
    for header in re.findall(r'<h4 class="code-header">(.*?)</h4>', inherent, re.S):
        print("  " + " ".join(text(header).split()))
    traits = between(page, 'id="trait-implementations-list"',
                     ['id="synthetic-implementations', 'id="blanket-implementations'])
    for header in re.findall(r'<h3 class="code-header">(.*?)</h3>', traits, re.S):
        print("  " + " ".join(text(header).split()))
PY
)
if [ "${1:-}" = "--bless" ]; then
  printf '%s\n' "$listing" > engine/public-api.txt
  echo "engine/public-api.txt written ($(head -1 engine/public-api.txt))"
elif ! diff -u engine/public-api.txt <(printf '%s\n' "$listing"); then
  echo "The engine's public API changed (above: - committed, + now)." >&2
  echo "If on purpose, run scripts/public-api.sh --bless and commit engine/public-api.txt." >&2
  exit 1
fi
