import sys, numpy as np, OpenImageIO as oiio
src, dst, P = sys.argv[1], sys.argv[2], int(sys.argv[3])
b = oiio.ImageBuf(src); px = b.get_pixels(oiio.FLOAT); spec=b.spec()
out = np.ascontiguousarray(px[P:-P, P:-P, :]) if P else px
s = oiio.ImageSpec(out.shape[1], out.shape[0], out.shape[2], oiio.FLOAT); s.channelnames = list(spec.channelnames)
o = oiio.ImageBuf(s); o.set_pixels(oiio.ROI(), out); o.write(dst)
