import numpy as np, json, sys
sys.path.insert(0, 'tools/experiments')
from scale_accuracy import STREAM
from diviewer.evaluate import score
from diviewer.gl.context import headless_context
from diviewer.gl.neural import NeuralPass
from diviewer.gl.renderer import Renderer
from diviewer.gl.area import AreaDirect
from diviewer.runtime import NeuralGI
from diviewer.scene import load_scene, sample_config
from diviewer.viewer.models import gi_resolution, runtime_pads
scene = load_scene('cornell'); W = H = 384; e = 0.642025732938584
truths = dict(np.load('runs/cornell/viewer_truth_384.npz'))
out = {}
for mp in ('assets/models/cornell.onnx', '/tmp/cornell_a4.onnx'):
    model = NeuralGI(mp, scene=scene)
    rows = {'viewer': [], 'viewer_direct_aa4': []}
    with headless_context() as ctx:
        r = Renderer(ctx, scene, W, H)
        gi = gi_resolution('model', (W, H), model.resolution, model.multiple, pads=runtime_pads(model), shape=(W, H))
        npass = NeuralPass(ctx, r, model, gi_size=gi)
        aa = AreaDirect(ctx, scene, W, H, 4)
        for split in ('train', 'test'):
            for i in range(4):
                seed = int(np.random.SeedSequence([STREAM, 0 if split == 'train' else 1, i]).generate_state(1)[0] & 0x7FFFFFFF)
                config = sample_config(scene, seed, split)
                truth = truths[f"cornell_{split}_{i}_{seed}_{W}x{H}_256"]
                r.render(config)
                npass.run(**npass.inputs_for(scene, config))
                full = np.flipud(np.frombuffer(npass.composite().read(), dtype='f2').reshape(H, W, 4)[..., :3]).astype(np.float32)
                ind = np.flipud(np.frombuffer(npass.composite(indirect_only=True).read(), dtype='f2').reshape(H, W, 4)[..., :3]).astype(np.float32)
                d_aa = aa(config)
                rows['viewer'].append(score(full, truth, e)['psnr_tm'])
                rows['viewer_direct_aa4'].append(score(ind + d_aa, truth, e)['psnr_tm'])
        aa.release(); npass.release(); r.release()
    out[mp] = {k: float(np.mean(v)) for k, v in rows.items()}
    print(mp, {k: round(v, 2) for k, v in out[mp].items()})
json.dump(out, open('/tmp/viewer_aa.json', 'w'), indent=1)
