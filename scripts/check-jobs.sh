#!/usr/bin/env bash
# Checks the job files of jobs/ without a cluster (README, "Rendering on a
# cluster"): the shell scripts and Slurm batch files parse and pass
# ShellCheck (installed with apt if missing and possible), the Kubernetes
# manifests parse as YAML
# and say what the README says they do (an Indexed Job whose pods run
# jobs/task.sh with their completion index and the task count, every pod on
# the shared volume; the merge Job runs `strata merge` on it). Running the
# tasks themselves is cli/tests/cli.rs's (through xargs -P).
set -euo pipefail
cd "$(dirname "$0")/.."
for f in jobs/*.sh jobs/*.sbatch; do
  bash -n "$f"
done
if ! command -v shellcheck >/dev/null && command -v apt-get >/dev/null && [ "$(id -u)" = 0 ]; then
  apt-get install -y -qq shellcheck >/dev/null 2>&1 || true
fi
if command -v shellcheck >/dev/null; then
  shellcheck jobs/*.sh jobs/*.sbatch
else
  echo "shellcheck is not installed: parsed with bash -n only"
fi
grep -q '^#SBATCH ' jobs/slurm-tasks.sbatch
grep -q 'SLURM_ARRAY_TASK_ID' jobs/slurm-tasks.sbatch
grep -q 'dependency=.afterany' jobs/slurm-submit.sh
python3 - <<'PY'
import re, sys, yaml

def job(path):
    with open(path) as f:
        docs = [d for d in yaml.safe_load_all(f) if d]
    assert len(docs) == 1, f"{path}: one document"
    d = docs[0]
    assert d["apiVersion"] == "batch/v1" and d["kind"] == "Job", path
    pod = d["spec"]["template"]["spec"]
    assert pod["restartPolicy"] in ("Never", "OnFailure"), path
    (container,) = pod["containers"]
    mounts = {m["name"]: m["mountPath"] for m in container["volumeMounts"]}
    claims = {v["name"] for v in pod["volumes"] if "persistentVolumeClaim" in v}
    assert set(mounts) <= claims, f"{path}: every mount is the shared claim"
    return d, " ".join(container["command"])

tasks, command = job("jobs/kubernetes.yaml")
spec = tasks["spec"]
assert spec["completionMode"] == "Indexed", "an Indexed Job"
count = int(re.search(r'task\.sh "\$JOB_COMPLETION_INDEX" (\d+)', command).group(1))
assert count == spec["completions"], "the task count is the completions"
merge, command = job("jobs/kubernetes-merge.yaml")
assert "strata merge" in command, "the merge job merges"
print(f"job files: Slurm scripts parse; Kubernetes: {count} indexed tasks and a merge")
PY
