import sys, numpy as np, OpenImageIO as oiio
def rd(f, ch=3): return oiio.ImageBuf(f).get_pixels(oiio.FLOAT)[:, :, :ch]
ref = rd(sys.argv[1])
for f in sys.argv[2:]:
    x = rd(f); e = ((x-ref)**2/(ref**2+1e-2)).mean(axis=2)
    H, W = e.shape; yy, xx = np.mgrid[:H, :W]; d = np.minimum(np.minimum(yy, xx), np.minimum(H-1-yy, W-1-xx))
    print(f, "total %.4e" % e.mean(), " ".join("r%d:%.3e" % (r, e[d==r].sum()/e.size) for r in range(6)), "inner(>=24): %.4e" % (e[d>=24].sum()/e.size))
