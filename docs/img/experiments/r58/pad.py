import sys, numpy as np, OpenImageIO as oiio
src, dst, P, mode = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4]
b = oiio.ImageBuf(src); spec = b.spec(); px = b.get_pixels(oiio.FLOAT)
names = list(spec.channelnames); H, W, C = px.shape
out = np.pad(px, ((P, P), (P, P), (0, 0)), mode=mode)
sign_x = np.ones((H + 2*P, W + 2*P), np.float32); sign_x[:, :P] = -1; sign_x[:, P+W:] = -1
sign_y = np.ones_like(sign_x); sign_y[:P, :] = -1; sign_y[P+H:, :] = -1
for i, n in enumerate(names):
    if n == 'N.X': out[:, :, i] *= sign_x
    if n == 'N.Y': out[:, :, i] *= sign_y
s = oiio.ImageSpec(W + 2*P, H + 2*P, C, oiio.FLOAT); s.channelnames = names
for a in spec.extra_attribs:
    if a.name.startswith('kpcn'): s.attribute(a.name, a.type, a.value)
o = oiio.ImageBuf(s); o.set_pixels(oiio.ROI(), out); o.write(dst)
