// A live OpenSubdiv reference for the tests: reads a mesh with tags and one command on
// stdin, prints the result as whitespace-separated numbers on stdout (%.17g).
//
// Input: "scheme boundary crease_method triangle_rule" (catmark|loop|bilinear,
// edge_only|edge_and_corner|none, uniform|chaikin, catmark|smooth), then "V F", V lines
// "x y z", F lines "n i0 .. i(n-1)", then "C" and C lines "a b sharpness", then "K" and
// K lines "v sharpness", then "H" and H face ids, then one command:
//   refine L    level-L vertices of uniform refinement ("count" then x y z per vertex)
//   limit L     PrimvarRefiner::Limit at the level-L vertices (x y z du dv per vertex)
//   patch L N   N lines "ptex_face u v": Far::PatchTable (adaptive to level L,
//               useInfSharpPatch, Gregory end caps) evaluated there (x y z du dv each)
//   ptex        Far::PtexIndices: the first ptex face of every face
#include <opensubdiv/far/patchMap.h>
#include <opensubdiv/far/patchTableFactory.h>
#include <opensubdiv/far/primvarRefiner.h>
#include <opensubdiv/far/ptexIndices.h>
#include <opensubdiv/far/topologyDescriptor.h>

#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

using namespace OpenSubdiv;

struct Point {
    double p[3];
    void Clear(void * = 0) { p[0] = p[1] = p[2] = 0.0; }
    void AddWithWeight(Point const &src, double w) {
        for (int k = 0; k < 3; ++k) p[k] += w * src.p[k];
    }
};

static void print(Point const &a) { std::printf("%.17g %.17g %.17g", a.p[0], a.p[1], a.p[2]); }

static std::vector<Point> verts;  // the control points

static Far::TopologyRefiner *read_refiner() {
    std::string scheme, boundary, crease, tri;
    std::cin >> scheme >> boundary >> crease >> tri;
    Sdc::SchemeType type = scheme == "loop" ? Sdc::SCHEME_LOOP
                         : scheme == "bilinear" ? Sdc::SCHEME_BILINEAR : Sdc::SCHEME_CATMARK;
    Sdc::Options opt;
    opt.SetVtxBoundaryInterpolation(
        boundary == "none" ? Sdc::Options::VTX_BOUNDARY_NONE
        : boundary == "edge_and_corner" ? Sdc::Options::VTX_BOUNDARY_EDGE_AND_CORNER
                                        : Sdc::Options::VTX_BOUNDARY_EDGE_ONLY);
    opt.SetCreasingMethod(crease == "chaikin" ? Sdc::Options::CREASE_CHAIKIN
                                              : Sdc::Options::CREASE_UNIFORM);
    opt.SetTriangleSubdivision(tri == "smooth" ? Sdc::Options::TRI_SUB_SMOOTH
                                               : Sdc::Options::TRI_SUB_CATMARK);
    static std::vector<int> sizes, indices, pairs, corners, holes;
    static std::vector<float> crease_w, corner_w;
    int V, F, C, K, H;
    std::cin >> V >> F;
    verts.resize(V);
    for (auto &v : verts) std::cin >> v.p[0] >> v.p[1] >> v.p[2];
    sizes.resize(F);
    for (int f = 0; f < F; ++f) {
        std::cin >> sizes[f];
        for (int i = 0, j; i < sizes[f]; ++i) { std::cin >> j; indices.push_back(j); }
    }
    std::cin >> C;
    for (int c = 0, a, b; c < C; ++c) {
        float s; std::cin >> a >> b >> s;
        pairs.push_back(a); pairs.push_back(b); crease_w.push_back(s);
    }
    std::cin >> K;
    for (int k = 0, v; k < K; ++k) { float s; std::cin >> v >> s; corners.push_back(v); corner_w.push_back(s); }
    std::cin >> H;
    for (int h = 0, f; h < H; ++h) { std::cin >> f; holes.push_back(f); }
    Far::TopologyDescriptor desc;
    desc.numVertices = V; desc.numFaces = F;
    desc.numVertsPerFace = sizes.data(); desc.vertIndicesPerFace = indices.data();
    desc.numCreases = C; desc.creaseVertexIndexPairs = pairs.data(); desc.creaseWeights = crease_w.data();
    desc.numCorners = K; desc.cornerVertexIndices = corners.data(); desc.cornerWeights = corner_w.data();
    desc.numHoles = H; desc.holeIndices = holes.data();
    typedef Far::TopologyRefinerFactory<Far::TopologyDescriptor> Factory;
    Far::TopologyRefiner *refiner = Factory::Create(desc, Factory::Options(type, opt));
    if (!refiner) { std::fprintf(stderr, "osd_driver: topology rejected\n"); std::exit(2); }
    return refiner;
}

static std::vector<Point> refine_all(Far::TopologyRefiner const &refiner, std::vector<Point> const &base) {
    std::vector<Point> all(refiner.GetNumVerticesTotal());
    std::copy(base.begin(), base.end(), all.begin());
    Far::PrimvarRefinerReal<double> primvar(refiner);
    Point *src = all.data();
    for (int level = 1; level <= refiner.GetMaxLevel(); ++level) {
        Point *dst = src + refiner.GetLevel(level - 1).GetNumVertices();
        primvar.Interpolate(level, src, dst);
        src = dst;
    }
    return all;
}

int main() {
    Far::TopologyRefiner *refiner = read_refiner();
    std::vector<Point> const &base = verts;
    std::string command;
    std::cin >> command;
    if (command == "ptex") {
        Far::PtexIndices ptex(*refiner);
        for (int f = 0; f < refiner->GetLevel(0).GetNumFaces(); ++f) std::printf("%d\n", ptex.GetFaceId(f));
        return 0;
    }
    int L; std::cin >> L;
    if (command == "refine" || command == "limit") {
        Far::TopologyRefiner::UniformOptions uniform(L);
        uniform.fullTopologyInLastLevel = true;  // Limit() needs the last level's edges
        refiner->RefineUniform(uniform);
        std::vector<Point> all = refine_all(*refiner, base);
        int n = refiner->GetLevel(L).GetNumVertices();
        Point *last = all.data() + all.size() - n;
        std::printf("%d\n", n);
        if (command == "refine") {
            for (int i = 0; i < n; ++i) { print(last[i]); std::printf("\n"); }
            return 0;
        }
        std::vector<Point> pos(n), du(n), dv(n);
        Far::PrimvarRefinerReal<double>(*refiner).Limit(last, pos, du, dv);
        for (int i = 0; i < n; ++i) {
            print(pos[i]); std::printf(" "); print(du[i]); std::printf(" "); print(dv[i]); std::printf("\n");
        }
        return 0;
    }
    // patch L N
    int N; std::cin >> N;
    Far::PatchTableFactory::Options popt(L);
    popt.SetEndCapType(Far::PatchTableFactory::Options::ENDCAP_GREGORY_BASIS);
    popt.useInfSharpPatch = true;
    popt.SetPatchPrecision<double>();
    refiner->RefineAdaptive(popt.GetRefineAdaptiveOptions());
    Far::PatchTable *table = Far::PatchTableFactory::Create(*refiner, popt);
    std::vector<Point> all = refine_all(*refiner, base);
    all.resize(refiner->GetNumVerticesTotal() + table->GetNumLocalPoints());
    if (table->GetNumLocalPoints())  // end-cap points, from double-precision stencils
        table->GetLocalPointStencilTable<double>()->UpdateValues(
            all.data(), all.data() + refiner->GetNumVerticesTotal());
    Far::PatchMap map(*table);
    double wp[20], wu[20], wv[20];
    for (int s = 0; s < N; ++s) {
        int face; double u, v;
        std::cin >> face >> u >> v;
        Far::PatchTable::PatchHandle const *handle = map.FindPatch(face, u, v);
        Point p, a, b; p.Clear(); a.Clear(); b.Clear();
        if (handle) {
            table->EvaluateBasis(*handle, u, v, wp, wu, wv);
            Far::ConstIndexArray cvs = table->GetPatchVertices(*handle);
            for (int k = 0; k < cvs.size(); ++k) {
                p.AddWithWeight(all[cvs[k]], wp[k]);
                a.AddWithWeight(all[cvs[k]], wu[k]);
                b.AddWithWeight(all[cvs[k]], wv[k]);
            }
        }
        print(p); std::printf(" "); print(a); std::printf(" "); print(b); std::printf("\n");
    }
    return 0;
}
