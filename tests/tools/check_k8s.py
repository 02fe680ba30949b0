#!/usr/bin/env python3
"""check_k8s.py — structural check of deploy/k8s/*.yaml with python3-yaml (Debian's kubectl,
kubernetes-client 1.20, and any kubectl need an API server even for --dry-run=client, so no
kubectl validation is possible offline).

  python3 tests/tools/check_k8s.py FILE...

Checks: each document parses and has apiVersion, kind and metadata.name, with the apiVersion the
kind lives in; a Deployment's selector matches its pod labels; every volumeMount names a volume
of the pod and every persistentVolumeClaim volume a claim; the splatd Deployment mounts its data
read-only from a claim, its cache from a claim, its token from a Secret, and has a TCP readiness
probe on a port it declares; the Service selects the Deployment's pods and targets that port;
the Indexed Job's SPLAT_SHARD_COUNT equals its completions and it runs `splat ... path` against
the Service's name and port. Prints one line per problem (FILE: DOC KIND/NAME: what) and exits 1
when there is any, else prints "ok: N documents" and exits 0."""
import sys
import yaml

API = {"Deployment": "apps/v1", "Service": "v1", "Job": "batch/v1",
       "PersistentVolumeClaim": "v1", "Secret": "v1", "ConfigMap": "v1"}
problems = []


def bad(where, msg):
    problems.append("%s: %s" % (where, msg))


def pod_checks(where, pod):
    vols = {v.get("name"): v for v in pod.get("volumes", [])}
    conts = pod.get("containers", []) + pod.get("initContainers", [])
    if not pod.get("containers"):
        bad(where, "no containers")
    for c in conts:
        if not c.get("image"):
            bad(where, "container %s has no image" % c.get("name"))
        for m in c.get("volumeMounts", []):
            if m.get("name") not in vols:
                bad(where, "container %s mounts unknown volume %s" % (c.get("name"), m.get("name")))
    for name, v in vols.items():
        if "persistentVolumeClaim" in v and not v["persistentVolumeClaim"].get("claimName"):
            bad(where, "volume %s: persistentVolumeClaim without claimName" % name)
    return vols


def mount_of(container, path):
    for m in container.get("volumeMounts", []):
        if m.get("mountPath") == path:
            return m
    return None


def arg_after(args, flag):
    return args[args.index(flag) + 1] if flag in args and args.index(flag) + 1 < len(args) else None


def main(files):
    docs = []
    for f in files:
        try:
            with open(f) as fh:
                for i, d in enumerate(yaml.safe_load_all(fh)):
                    if d is not None:
                        docs.append(("%s: doc %d" % (f, i + 1), d))
        except (OSError, yaml.YAMLError) as e:
            bad(f, "does not parse: %s" % e)
    by_kind = {}
    for where, d in docs:
        kind = d.get("kind")
        name = (d.get("metadata") or {}).get("name")
        if not d.get("apiVersion") or not kind or not name:
            bad(where, "needs apiVersion, kind and metadata.name")
            continue
        where = "%s %s/%s" % (where, kind, name)
        if kind in API and d["apiVersion"] != API[kind]:
            bad(where, "apiVersion %s, expected %s" % (d["apiVersion"], API[kind]))
        by_kind.setdefault(kind, []).append((where, d))

    deps = by_kind.get("Deployment", [])
    svcs = by_kind.get("Service", [])
    jobs = by_kind.get("Job", [])
    for want, lst in (("Deployment", deps), ("Service", svcs), ("Job", jobs)):
        if not lst:
            bad("manifests", "no %s" % want)
    port_name, port_num, labels = None, None, {}
    for where, d in deps:
        spec = d.get("spec", {})
        tmpl = spec.get("template", {})
        labels = (tmpl.get("metadata") or {}).get("labels") or {}
        sel = (spec.get("selector") or {}).get("matchLabels") or {}
        if not sel or any(labels.get(k) != v for k, v in sel.items()):
            bad(where, "selector %s does not match the pod labels %s" % (sel, labels))
        pod = tmpl.get("spec", {})
        vols = pod_checks(where, pod)
        c = next((c for c in pod.get("containers", []) if "splatd" in (c.get("command") or [])), None)
        if not c:
            bad(where, "no container runs splatd")
            continue
        args = c.get("args", [])
        data, cache, tok = arg_after(args, "--data"), arg_after(args, "--cache"), arg_after(args, "--token-file")
        if not data or not cache or not tok:
            bad(where, "splatd needs --data, --cache and --token-file")
            continue
        m = mount_of(c, data)
        if not m or not m.get("readOnly") or "persistentVolumeClaim" not in vols.get(m.get("name"), {}):
            bad(where, "the data directory %s is not a read-only mount of a claim" % data)
        cm = next((mount_of(c, p) for p in [cache.rsplit("/", i)[0] for i in range(cache.count("/"))]
                   if p and mount_of(c, p)), None)
        if not cm or "persistentVolumeClaim" not in vols.get(cm.get("name"), {}):
            bad(where, "the cache %s is not on a persistent volume claim" % cache)
        # the token: a Secret volume, copied (mode 0600) by an init container, or mounted directly
        secret_vols = [n for n, v in vols.items() if "secret" in v]
        if not secret_vols:
            bad(where, "no Secret volume for the token")
        tdir = tok.rsplit("/", 1)[0]
        tm = mount_of(c, tdir) or mount_of(c, tok)
        if not tm:
            bad(where, "the token file %s is on no mount" % tok)
        elif tm.get("name") not in secret_vols:
            inits = pod.get("initContainers", [])
            if not any(mount_of(ic, tdir) and any(mount_of(ic, m2.get("mountPath")) for m2 in
                       ic.get("volumeMounts", []) if m2.get("name") in secret_vols) and
                       "0600" in " ".join(ic.get("command", []) + ic.get("args", [])) for ic in inits):
                bad(where, "the token's mount %s is neither the Secret nor filled from it (mode 0600) "
                    "by an init container" % tdir)
        rp = c.get("readinessProbe") or {}
        tcp = rp.get("tcpSocket")
        ports = {p.get("name"): p.get("containerPort") for p in c.get("ports", [])}
        listen = arg_after(args, "--listen") or ""
        if not tcp:
            bad(where, "readinessProbe is not a tcpSocket probe")
        else:
            p = tcp.get("port")
            num = ports.get(p, p)
            if num not in ports.values():
                bad(where, "the readiness probe's port %s is not a declared container port" % p)
            if not listen.endswith(":%s" % num):
                bad(where, "splatd listens on '%s', the probe checks port %s" % (listen, num))
            port_name, port_num = p, num
    svc_name, svc_port = None, None
    for where, d in svcs:
        spec = d.get("spec", {})
        sel = spec.get("selector") or {}
        if not sel or any(labels.get(k) != v for k, v in sel.items()):
            bad(where, "selector %s selects no Deployment pods (labels %s)" % (sel, labels))
        ps = spec.get("ports") or []
        if not ps or ps[0].get("targetPort") not in (port_name, port_num):
            bad(where, "targetPort is not the daemon's port %s" % port_name)
        svc_name, svc_port = d["metadata"]["name"], ps[0].get("port") if ps else None
    for where, d in jobs:
        spec = d.get("spec", {})
        if spec.get("completionMode") != "Indexed":
            bad(where, "completionMode is not Indexed (JOB_COMPLETION_INDEX is not set otherwise)")
        pod = spec.get("template", {}).get("spec", {})
        if pod.get("restartPolicy") not in ("OnFailure", "Never"):
            bad(where, "a Job's restartPolicy must be OnFailure or Never")
        pod_checks(where, pod)
        for c in pod.get("containers", []):
            args = (c.get("command") or []) + (c.get("args") or [])
            if "splat" not in args[:1] or "path" not in args:
                bad(where, "container %s does not run splat path" % c.get("name"))
                continue
            env = {e.get("name"): e.get("value") for e in c.get("env", [])}
            if str(env.get("SPLAT_SHARD_COUNT")) != str(spec.get("completions")):
                bad(where, "SPLAT_SHARD_COUNT %s is not the completions %s" %
                    (env.get("SPLAT_SHARD_COUNT"), spec.get("completions")))
            if "--shard" in args:
                bad(where, "--shard fixes one index for every pod")
            if arg_after(args, "--host") != svc_name or str(arg_after(args, "--port")) != str(svc_port):
                bad(where, "splat talks to %s:%s, the Service is %s:%s" %
                    (arg_after(args, "--host"), arg_after(args, "--port"), svc_name, svc_port))
            out = arg_after(args, "-o") or ""
            if not any(out.startswith(m.get("mountPath", "//") + "/") for m in c.get("volumeMounts", [])):
                bad(where, "the frames %s are not written to a volume" % out)
    for p in problems:
        print(p)
    if not problems:
        print("ok: %d documents" % len(docs))
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
