#!/usr/bin/env python3
"""Import circles among a crate's modules: `scripts/import-circles.py DIR`
(a crate's src/) prints every circle of modules that import one another
(`use crate::...`, `use super::...`, a parent's paths into its children, `self::child::` too;
tests and doc comments left out) and exits 1 if there is one. With
`--parents`, a module that imports from its parent module fails too (the
engine's rule: a parent re-exports its children, they import one another).
CI runs it, with `--parents`, on every crate (a module's imports from the
crate's root are not its parent's)."""
import os,re,collections,sys
args=[a for a in sys.argv[1:] if a != '--parents']
parents='--parents' in sys.argv[1:]
root=args[0] if args else 'engine/src'
os.chdir(root)
files=[]
for r,_,fs in os.walk('.'):
    for f in fs:
        if f.endswith('.rs'): files.append(os.path.join(r,f)[2:])
def modpath(f):
    p=f[:-3].split('/')
    if p[-1] in ('mod','lib','main'): p=p[:-1]
    return tuple(p)
mods={modpath(f):f for f in files}
edges=collections.defaultdict(set)
for m,f in mods.items():
    lines=open(f).read().split('\n')
    src=[]
    for l in lines:
        if l.strip().startswith('#[cfg(') and 'test' in l and not 'test-hooks' in l: break
        if l.strip().startswith('//'): continue
        src.append(l)
    src='\n'.join(src)
    is_mod=f.endswith(('mod.rs','lib.rs','main.rs'))
    refs=re.findall(r'\b((?:crate|super)(?:::\w+)+)',src)
    for head, group in re.findall(r'\b((?:crate|super)(?:::\w+)*)::\{([^}]*)\}', src):
        for item in group.split(','):
            item=item.strip().split(' as ')[0]
            if item and item!='self': refs.append(head+'::'+item)
            elif item=='self': refs.append(head)
    for u in refs:
        parts=u.split('::')
        if parts[0]=='crate': cur=[]; rest=parts[1:]
        else:
            cur=list(m)[:-1]; rest=parts[1:]
            while rest and rest[0]=='super': cur=cur[:-1]; rest=rest[1:]
        target=None
        for i in range(len(rest),0,-1):
            t=tuple(cur+rest[:i])
            if t in mods: target=t; break
        if target is None: target=tuple(cur)
        if target in mods and target!=m: edges[m].add(target)
    # A parent's own paths into its children (`child::item`, `self::child::item`, `use child::`).
    if is_mod:
        for child in re.findall(r'^\s*(?:pub(?:\([^)]*\))?\s+)?mod\s+(\w+);', src, re.M):
            if re.search(r'(?:(?<![:\w])|(?<=\bself::))' + child + r'::', src):
                edges[m].add(tuple(list(m) + [child]))
index={};low={};stack=[];on=set();sccs=[];i=[0]
sys.setrecursionlimit(10000)
def sc(v):
    index[v]=low[v]=i[0];i[0]+=1;stack.append(v);on.add(v)
    for w in edges[v]:
        if w not in index: sc(w); low[v]=min(low[v],low[w])
        elif w in on: low[v]=min(low[v],index[w])
    if low[v]==index[v]:
        c=[]
        while True:
            w=stack.pop();on.discard(w);c.append(w)
            if w==v: break
        if len(c)>1: sccs.append(c)
for v in list(mods):
    if v not in index: sc(v)
for c in sccs:
    names=sorted('::'.join(x) or 'lib' for x in c)
    print(len(c), names)
    for a in c:
        for b in edges[a]:
            if b in c: print('   ', '::'.join(a) or 'lib', '->', '::'.join(b) or 'lib')
upward=[(a,b) for a in mods for b in edges[a] if a[:-1]==b and len(a)>1]
if parents:
    for a,b in sorted(upward):
        print('imports its parent:', '::'.join(a), '->', '::'.join(b))
sys.exit(1 if sccs or (parents and upward) else 0)
