#include "core/simplify/simplify_region.h"

#include <OpenMesh/Core/Mesh/TriMesh_ArrayKernelT.hh>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <optional>

#include "core/mesh/mesh_quality.h"

namespace isotile {

namespace {

struct Traits : OpenMesh::DefaultTraits {
  using Point = OpenMesh::Vec3d;
  VertexAttributes(OpenMesh::Attributes::Status);
  EdgeAttributes(OpenMesh::Attributes::Status);
  FaceAttributes(OpenMesh::Attributes::Status);
};
using OMesh = OpenMesh::TriMesh_ArrayKernelT<Traits>;
using P = OpenMesh::Vec3d;
using VH = OMesh::VertexHandle;
using HH = OMesh::HalfedgeHandle;
using EH = OMesh::EdgeHandle;
using FH = OMesh::FaceHandle;

Vec3d arr(const P& p) {
  return {p[0], p[1], p[2]};
}
P vec(const Vec3d& p) {
  return {p[0], p[1], p[2]};
}

double quality(const P& a, const P& b, const P& c) {
  return radius_ratio_of_lengths((b - c).norm(), (c - a).norm(), (a - b).norm());
}

// Unnormalised normal (twice the area).
P cross_normal(const P& a, const P& b, const P& c) {
  return (b - a) % (c - a);
}

// The closest distance between segments a-b and c-d.
double segment_gap(const P& a, const P& b, const P& c, const P& d) {
  const P u = b - a, v = d - c, w = a - c;
  const double uu = u | u, uv = u | v, vv = v | v, uw = u | w, vw = v | w;
  const double den = uu * vv - uv * uv;
  double s = 0, t = 0;
  if (den > 1e-300) {
    s = std::clamp((uv * vw - vv * uw) / den, 0.0, 1.0);
    t = std::clamp((uu * vw - uv * uw) / den, 0.0, 1.0);
  }
  return ((a + s * u) - (c + t * v)).norm();
}

// Squared distance from p to triangle abc (Ericson, Real-Time Collision Detection, 5.1.5).
double point_triangle_distance2(const P& p, const P& a, const P& b, const P& c) {
  const P ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab | ap, d2 = ac | ap;
  if (d1 <= 0 && d2 <= 0) return ap.sqrnorm();
  const P bp = p - b;
  const double d3 = ab | bp, d4 = ac | bp;
  if (d3 >= 0 && d4 <= d3) return bp.sqrnorm();
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return (ap - (d1 / (d1 - d3)) * ab).sqrnorm();
  const P cp = p - c;
  const double d5 = ab | cp, d6 = ac | cp;
  if (d6 >= 0 && d5 <= d6) return cp.sqrnorm();
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return (ap - (d2 / (d2 - d6)) * ac).sqrnorm();
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const double w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return (bp - w * (c - b)).sqrnorm();
  }
  const double denom = 1 / (va + vb + vc);
  const double v = vb * denom, w = vc * denom;
  return (ap - v * ab - w * ac).sqrnorm();
}

// An indexed binary min-heap of edges keyed by (cost, edge index): ties break by index, so the
// order is deterministic.
class EdgeHeap {
 public:
  explicit EdgeHeap(std::size_t edges) : pos_(edges, -1), cost_(edges, 0) {}
  bool empty() const { return heap_.empty(); }
  bool contains(int e) const { return pos_[e] >= 0; }
  int top() const { return heap_.front(); }
  double top_cost() const { return cost_[heap_.front()]; }
  void costs(std::vector<double>& out) const {
    for (int e : heap_) out.push_back(cost_[e]);
  }
  void set(int e, double cost) {
    cost_[e] = cost;
    if (pos_[e] < 0) {
      pos_[e] = static_cast<int>(heap_.size());
      heap_.push_back(e);
      up(pos_[e]);
    } else {
      up(pos_[e]);
      down(pos_[e]);
    }
  }
  void remove(int e) {
    const int i = pos_[e];
    if (i < 0) return;
    const int last = heap_.back();
    heap_.pop_back();
    pos_[e] = -1;
    if (last == e) return;
    heap_[i] = last;
    pos_[last] = i;
    up(i);
    down(pos_[last]);
  }

 private:
  bool less(int a, int b) const { return cost_[a] < cost_[b] || (cost_[a] == cost_[b] && a < b); }
  void up(int i) {
    while (i > 0) {
      const int p = (i - 1) / 2;
      if (!less(heap_[i], heap_[p])) break;
      swap(i, p);
      i = p;
    }
  }
  void down(int i) {
    const int n = static_cast<int>(heap_.size());
    for (;;) {
      int m = i;
      const int l = 2 * i + 1, r = l + 1;
      if (l < n && less(heap_[l], heap_[m])) m = l;
      if (r < n && less(heap_[r], heap_[m])) m = r;
      if (m == i) break;
      swap(i, m);
      i = m;
    }
  }
  void swap(int i, int j) {
    std::swap(heap_[i], heap_[j]);
    pos_[heap_[i]] = i;
    pos_[heap_[j]] = j;
  }
  std::vector<int> heap_;
  std::vector<int> pos_;
  std::vector<double> cost_;
};

// The point of the line x + t n where the quadric is smallest (x when the quadric is flat along
// n).
P onto_quadric(const Quadric& q, const P& x, const P& n) {
  const auto& a = q.m;
  const P ax(a[0] * x[0] + a[1] * x[1] + a[2] * x[2] + a[6],
             a[1] * x[0] + a[3] * x[1] + a[4] * x[2] + a[7],
             a[2] * x[0] + a[4] * x[1] + a[5] * x[2] + a[8]);
  const P an(a[0] * n[0] + a[1] * n[1] + a[2] * n[2], a[1] * n[0] + a[3] * n[1] + a[4] * n[2],
             a[2] * n[0] + a[4] * n[1] + a[5] * n[2]);
  const double nan = n | an;
  if (!(nan > 1e-12 * q.trace())) return x;
  return x - ((n | ax) / nan) * n;
}

}  // namespace

struct RegionSimplifier::Impl {
  Impl(Region r, const RegionOptions& o) : region(std::move(r)), opt(o) { build(); }

  // --- setup -----------------------------------------------------------------------------------

  void build() {
    const std::size_t nv = region.positions.size();
    mesh.reserve(nv, region.triangles.size() * 3 / 2 + 3, region.triangles.size());
    for (const Vec3d& p : region.positions) mesh.add_vertex(vec(p));
    locked = region.locked;
    // OpenMesh reports faces it cannot link on its error stream, once per face; they are handled
    // here, so the stream is silenced (once, for the process: toggling it per region would race).
    static const bool silenced = [] {
      omerr().disable();
      return true;
    }();
    (void)silenced;
    std::vector<int> face_of(region.triangles.size(), -1);  // input triangle -> face, or -1
    for (std::size_t i = 0; i < region.triangles.size(); ++i) {
      const Tri& t = region.triangles[i];
      // A repeated corner never goes to OpenMesh: some such faces it refuses, others fail an
      // assertion in add_face (a face after one with the same corners twice: the process ends).
      const bool repeated = t[0] == t[1] || t[1] == t[2] || t[0] == t[2];
      const FH f = repeated ? FH() : mesh.add_face(VH(t[0]), VH(t[1]), VH(t[2]));
      if (f.is_valid()) {
        face_of[i] = f.idx();
      } else {
        face_of[i] = -2 - static_cast<int>(unlinked.size());
        unlinked.push_back(t);
      }
    }
    if (opt.max_error > 0) {
      face_head.assign(mesh.n_faces(), -1);
      pt_next.assign(region.points.size(), -1);
      for (std::size_t i = 0; i < region.points.size(); ++i) {
        const int f = face_of[region.point_face[i]];
        if (f >= 0) {
          pt_next[i] = face_head[f];
          face_head[f] = static_cast<int>(i);
        } else {
          fixed_points.push_back({static_cast<int>(i), -2 - f});  // on a face that never changes
        }
      }
    }
    // Faces OpenMesh refuses (a configuration it cannot link) pass through as they are; their
    // corners stay put so that they still fit.
    for (const Tri& t : unlinked)
      for (std::uint32_t v : t) locked[v] = 1;
    stats.unlinked_faces = unlinked.size();
    live_faces = mesh.n_faces();
    for (VH v : mesh.vertices())
      if (mesh.is_boundary(v) || mesh.is_isolated(v)) locked[v.idx()] = 1;
    heap.emplace(mesh.n_edges());
    for (EH e : mesh.edges()) update_edge(e);
  }

  bool is_locked(VH v) const { return locked[v.idx()] != 0; }
  const Quadric& quadric(VH v) const { return region.quadrics[v.idx()]; }

  // --- costs -----------------------------------------------------------------------------------

  struct Candidate {
    HH h;          // collapse from_vertex(h) into to_vertex(h)
    P x;           // where to_vertex(h) goes
    double cost;   // heap key
    double error;  // quadric error at x (sum of squared plane distances)
  };

  // The collapse an edge would make, or none (both ends locked).
  bool candidate(EH e, Candidate& c) const {
    HH h = mesh.halfedge_handle(e, 0);
    VH from = mesh.from_vertex_handle(h), to = mesh.to_vertex_handle(h);
    const bool lf = is_locked(from), lt = is_locked(to);
    if (lf && lt) return false;
    if (lf) {
      h = mesh.opposite_halfedge_handle(h);
      std::swap(from, to);
    }
    Quadric q = quadric(from);
    q += quadric(to);
    const P pf = mesh.point(from), pt = mesh.point(to);
    // Into a locked end, which stays where it is; else the regularised optimum.
    const P x = (lf || lt) ? pt : place(q, 0.5 * (pf + pt));
    c.h = h;
    c.x = x;
    c.error = q(arr(x));
    c.cost = c.error + opt.length_weight * q.trace() * 0.25 * (pf - pt).sqrnorm();
    return true;
  }

  // argmin q(x) + w |x - m|^2, w a small fraction of the planes' weight: the quadric's optimum
  // where it is well determined, the midpoint along directions it leaves free (flat regions,
  // creases), which keeps vertices evenly spread there.
  P place(const Quadric& q, const P& m) const {
    const auto& a = q.m;
    const double w = std::max(opt.placement_pull * q.trace(), 1e-12);
    const double m00 = a[0] + w, m01 = a[1], m02 = a[2], m11 = a[3] + w, m12 = a[4], m22 = a[5] + w;
    const double r0 = w * m[0] - a[6], r1 = w * m[1] - a[7], r2 = w * m[2] - a[8];
    // Cramer's rule on the symmetric positive definite 3x3 system.
    const double c00 = m11 * m22 - m12 * m12, c01 = m02 * m12 - m01 * m22,
                 c02 = m01 * m12 - m02 * m11;
    const double det = m00 * c00 + m01 * c01 + m02 * c02;
    if (!(std::abs(det) > 1e-300)) return m;
    const double c11 = m00 * m22 - m02 * m02, c12 = m01 * m02 - m00 * m12,
                 c22 = m00 * m11 - m01 * m01;
    return P{(c00 * r0 + c01 * r1 + c02 * r2) / det, (c01 * r0 + c11 * r1 + c12 * r2) / det,
             (c02 * r0 + c12 * r1 + c22 * r2) / det};
  }

  void update_edge(EH e) {
    Candidate c;
    if (!mesh.status(e).deleted() && candidate(e, c))
      heap->set(e.idx(), c.cost);
    else
      heap->remove(e.idx());
  }

  // --- checks ----------------------------------------------------------------------------------

  // OpenMesh's link condition lets a tetrahedron collapse into two triangles back to back: every
  // vertex must keep at least three neighbours. Collapsing edge (from, to) of faces (to, from,
  // c) and (from, to, d) joins the two ends' neighbours less the two shared, and takes one from c
  // and from d.
  bool valences_ok(HH h) const {
    const HH o = mesh.opposite_halfedge_handle(h);
    const VH from = mesh.to_vertex_handle(o), to = mesh.to_vertex_handle(h);
    if (mesh.valence(from) + mesh.valence(to) < 7) return false;
    for (HH x : {h, o}) {
      if (mesh.is_boundary(x)) continue;
      if (mesh.valence(mesh.to_vertex_handle(mesh.next_halfedge_handle(x))) < 4) return false;
    }
    return true;
  }

  // Locked vertices may be shared with other regions, which cannot see this one's edges: a new
  // edge between two of them could meet the same new edge made on the other side, and the two
  // would join into a non-manifold edge. Collapsing `from` into `to` joins `to` to every
  // neighbour of `from`; with `to` locked, each locked one must already be its neighbour.
  bool locked_links_ok(VH from, VH to) const {
    if (!is_locked(to)) return true;
    for (VH n : mesh.vv_range(from))
      if (n != to && is_locked(n) && !mesh.find_halfedge(to, n).is_valid()) return false;
    return true;
  }

  // Copies of one split input vertex must never become neighbours of one vertex (or of each
  // other): welded back together they would make a non-manifold edge. Counts the distinct
  // vertices of each group among a, b and their neighbours; more than one of a group is refused.
  bool copies_ok(VH a, VH b) const {
    if (region.group.empty()) return true;
    pairs.clear();
    auto note = [&](VH v) {
      if (region.group[v.idx()] >= 0) pairs.push_back({region.group[v.idx()], v.idx()});
    };
    note(a);
    note(b);
    for (VH v : {a, b})
      for (VH n : mesh.vv_range(v)) note(n);
    std::sort(pairs.begin(), pairs.end());
    pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
    for (std::size_t i = 1; i < pairs.size(); ++i)
      if (pairs[i].first == pairs[i - 1].first) return false;
    return true;
  }

  // For a collapse of `from` into `to`: the above for the pair, and, when `to` is a copy, for
  // each neighbour of `from`, which becomes a neighbour of `to`.
  bool collapse_copies_ok(VH from, VH to) const {
    if (region.group.empty()) return true;
    if (!copies_ok(from, to)) return false;
    const std::int32_t g = region.group[to.idx()];
    if (g < 0) return true;
    for (VH n : mesh.vv_range(from))
      for (VH m : mesh.vv_range(n))
        if (m != to && region.group[m.idx()] == g) return false;
    return true;
  }

  // The worst radius ratio of the faces around v.
  double worst_around(VH v) const {
    double worst = 1;
    for (FH f : mesh.vf_range(v)) {
      auto it = mesh.cfv_iter(f);
      const P a = mesh.point(*it), b = mesh.point(*++it), c = mesh.point(*++it);
      worst = std::min(worst, quality(a, b, c));
    }
    return worst;
  }

  // The area vector of the input surface v stands for (see Quadric::area), and its area.
  P area(VH v) const { return vec(region.quadrics[v.idx()].area); }
  double area_sum(VH v) const { return region.quadrics[v.idx()].area_sum; }

  // Whether a face that becomes `after` (unnormalised normals) from `before` faces within the
  // allowed angle of `ref`, the area vectors of its corners summed (the input surface it stands
  // for). The check against the face's last shape (max_normal_turn) bounds each step, not their
  // sum, and says nothing where the face is degenerate (Marching Cubes makes zero-area faces and
  // specks around samples equal to the isovalue): alone, it lets a face turn over a step at a
  // time, or grow from a speck turned over, and a vertex fold past the locked border.
  //
  // A face beyond the limit may only come from one already beyond it, turning no further from
  // `ref` and with no more of its (doubled) area beyond the limit (its deficit: its projection
  // short of the limit's), or be a speck: a deficit within a negligible share (input_slack) of the
  // corners' input area, which lets collapses among zero-area faces go on. So the input's own
  // folds may still be worked on, but no face turns over or grows turned over. Where the input
  // faces in many directions (|ref| below input_coherence times the area `sum`: thin twigs and
  // sheets, whose two sides the corners share) there is no direction to keep.
  bool faces_input(const P& after, const P& before, const P& ref, double sum) const {
    const double lr = ref.norm();
    if (!(lr > 0) || lr < opt.input_coherence * sum) return true;
    const P r = ref / lr;
    const double la = after.norm(), lb = before.norm();
    const double ca = (after | r) / la;
    if (ca >= opt.max_input_turn) return true;
    const double deficit = opt.max_input_turn * la - (after | r);
    if (deficit <= 2 * opt.input_slack * sum) return true;
    return lb > 0 && ca >= (before | r) / lb && deficit <= opt.max_input_turn * lb - (before | r);
  }

  // How worst_after_move counts a face of no area that stays so: skipped, or as a radius ratio of
  // 0 (as worst_around counts it).
  enum class Flat { Skip, Zero };

  // Shape and normals of the faces around v after v moves to x, skipping f0 and f1 (the faces a
  // collapse removes), with `other` (the collapse's other end) also at x. Returns the worst new
  // radius ratio, or -1 when a face would turn too far, from its last shape or from the input.
  double worst_after_move(VH v, VH other, const P& x, FH f0 = FH(), FH f1 = FH(),
                          Flat flat = Flat::Skip) const {
    double worst = 1;
    // After a collapse the vertex at x stands for both ends' surface. (Only f0 and f1 hold both.)
    const P merged = other == v ? area(v) : area(v) + area(other);
    const double merged_sum = other == v ? area_sum(v) : area_sum(v) + area_sum(other);
    for (FH f : mesh.vf_range(v)) {
      if (f == f0 || f == f1) continue;
      P p[3], n[3], ref(0, 0, 0);
      double sum = 0;
      int k = 0;
      for (VH u : mesh.fv_range(f)) {
        p[k] = mesh.point(u);
        const bool moved = u == v || u == other;
        n[k] = moved ? x : p[k];
        ref += moved ? merged : area(u);
        sum += moved ? merged_sum : area_sum(u);
        ++k;
      }
      const P before = cross_normal(p[0], p[1], p[2]), after = cross_normal(n[0], n[1], n[2]);
      const double lb = before.norm(), la = after.norm();
      // A face of no area that stays so (Marching Cubes makes fans of them where samples equal
      // the isovalue, their corners at one point) is not made worse: judged, it refused every
      // collapse in such a fan (each leaves the others), and the fans stayed whole. The cleanup's
      // moves count it (Flat::Zero): they are there to lift the worst triangle, and one that
      // stays of no area is not lifted. Skipped there, every move looked like a lift from 0 and
      // the vertex of such a face between two locked corners at one point walked off the
      // surface a step per cleanup visit (engine's Marching Cubes mesh at 100: 3 voxels, on the
      // volume's z = 0 border).
      if (la == 0 && lb == 0) {
        if (flat == Flat::Zero) worst = 0;
        continue;
      }
      if (la == 0) return -1;
      if (lb > 0 && (before | after) < opt.max_normal_turn * lb * la) return -1;
      if (!faces_input(after, before, ref, sum)) return -1;
      worst = std::min(worst, quality(n[0], n[1], n[2]));
    }
    return worst;
  }

  bool within_error(const Candidate& c) const {
    return opt.max_error <= 0 || c.error <= opt.max_error * opt.max_error;
  }

  // The worst triangle left around the collapse, or -1 when it is not allowed for topology or
  // normals.
  double collapse_worst(const Candidate& c) {
    const VH from = mesh.from_vertex_handle(c.h), to = mesh.to_vertex_handle(c.h);
    if (!mesh.is_collapse_ok(c.h) || !valences_ok(c.h) || !locked_links_ok(from, to) ||
        !collapse_copies_ok(from, to)) {
      ++stats.refused_topology;
      return -1;
    }
    const FH f0 = mesh.face_handle(c.h), f1 = mesh.opposite_face_handle(c.h);
    const double a = worst_after_move(from, to, c.x, f0, f1);
    const double b = a < 0 ? -1 : worst_after_move(to, from, c.x, f0, f1);
    if (b < 0) {
      ++stats.refused_normal;
      return -1;
    }
    return std::min(a, b);
  }

  void apply_collapse(const Candidate& c) {
    const VH from = mesh.from_vertex_handle(c.h), to = mesh.to_vertex_handle(c.h);
    live_faces -= mesh.is_boundary(mesh.edge_handle(c.h)) ? 1 : 2;
    region.quadrics[to.idx()] += region.quadrics[from.idx()];
    for (HH h : mesh.voh_range(from)) heap->remove(mesh.edge_handle(h).idx());
    mesh.collapse(c.h);
    mesh.set_point(to, c.x);
    if (opt.max_error > 0) reattach(new_faces);  // as collapse_fits left them
    // The edges at `to` have new costs; the edges one ring further keep theirs but have new
    // neighbourhoods, so those that were refused (out of the heap) get another chance.
    for (HH h : mesh.voh_range(to)) update_edge(mesh.edge_handle(h));
    for (VH n : mesh.vv_range(to))
      for (HH h : mesh.voh_range(n)) {
        const EH e = mesh.edge_handle(h);
        if (!heap->contains(e.idx())) update_edge(e);
      }
  }

  // --- the error bound --------------------------------------------------------------------------

  struct NewFace {
    FH f;  // the face that will hold this triangle (for flips: decided after the flip)
    P a, b, c;
  };

  // Whether every point attached to `old_faces` lies within the bound of one of `tris`; if so,
  // `best` gets, per point gathered in `gathered`, the index of its nearest new triangle.
  bool points_fit(std::initializer_list<VH> fans, const std::vector<NewFace>& tris) {
    gathered.clear();
    faces_seen.clear();
    for (VH v : fans)
      for (FH f : mesh.vf_range(v)) faces_seen.push_back(f.idx());
    return points_fit_faces(tris);
  }

  bool points_fit_faces(const std::vector<NewFace>& tris) {
    std::sort(faces_seen.begin(), faces_seen.end());
    faces_seen.erase(std::unique(faces_seen.begin(), faces_seen.end()), faces_seen.end());
    gathered.clear();
    for (int f : faces_seen)
      for (int i = face_head[f]; i >= 0; i = pt_next[i]) gathered.push_back(i);
    best.resize(gathered.size());
    const double bound = opt.max_error * opt.max_error;
    for (std::size_t k = 0; k < gathered.size(); ++k) {
      const P pt = vec(region.points[gathered[k]]);
      double d = HUGE_VAL;
      for (std::size_t t = 0; t < tris.size(); ++t) {
        const double dt = point_triangle_distance2(pt, tris[t].a, tris[t].b, tris[t].c);
        if (dt < d) {
          d = dt;
          best[k] = static_cast<int>(t);
        }
      }
      if (d > bound) return false;
    }
    return true;
  }

  // After the change: the gathered points move to the faces points_fit chose.
  void reattach(const std::vector<NewFace>& tris) {
    for (int f : faces_seen) face_head[f] = -1;
    for (std::size_t k = 0; k < gathered.size(); ++k) {
      const int f = tris[best[k]].f.idx();
      pt_next[gathered[k]] = face_head[f];
      face_head[f] = gathered[k];
    }
  }

  // The faces around v (and `other`) after both move to x, skipping f0 and f1.
  void faces_after_move(VH v, VH other, const P& x, FH f0, FH f1, std::vector<NewFace>& out) {
    for (VH w : {v, other})
      for (FH f : mesh.vf_range(w)) {
        if (f == f0 || f == f1) continue;
        if (w == other && face_has(f, v)) continue;  // listed from v already
        P p[3];
        int k = 0;
        for (VH u : mesh.fv_range(f)) p[k++] = (u == v || u == other) ? x : mesh.point(u);
        out.push_back({f, p[0], p[1], p[2]});
      }
  }

  bool face_has(FH f, VH v) const {
    for (VH u : mesh.fv_range(f))
      if (u == v) return true;
    return false;
  }

  bool collapse_fits(const Candidate& c) {
    if (opt.max_error <= 0) return true;
    const VH from = mesh.from_vertex_handle(c.h), to = mesh.to_vertex_handle(c.h);
    new_faces.clear();
    faces_after_move(from, to, c.x, mesh.face_handle(c.h), mesh.opposite_face_handle(c.h),
                     new_faces);
    return !new_faces.empty() && points_fit({from, to}, new_faces);
  }

  bool move_fits(VH v, const P& x) {
    if (opt.max_error <= 0) return true;
    new_faces.clear();
    faces_after_move(v, v, x, FH(), FH(), new_faces);
    return points_fit({v}, new_faces);
  }

  // --- 1. collapses ----------------------------------------------------------------------------

  std::uint64_t collapse(double max_cost, std::uint64_t max_collapses, const Progress* progress) {
    std::uint64_t made = 0;
    for (std::uint64_t taken = 0;
         made < max_collapses && !heap->empty() && heap->top_cost() <= max_cost; ++taken) {
      if ((taken & 1023) == 1023) progress_check(progress);
      const EH e(heap->top());
      heap->remove(e.idx());
      Candidate c;
      if (!candidate(e, c)) continue;
      if (!within_error(c)) continue;  // its error only grows: it never comes back
      const double worst = collapse_worst(c);
      if (worst < 0) continue;  // waits outside the heap until a neighbour's collapse changes it
      if (worst < opt.min_quality) {
        const VH from = mesh.from_vertex_handle(c.h), to = mesh.to_vertex_handle(c.h);
        if (worst <= std::min(worst_around(from), worst_around(to))) {
          ++stats.refused_shape;
          continue;
        }
      }
      if (!collapse_fits(c)) {
        ++stats.refused_error;
        continue;
      }
      apply_collapse(c);
      ++stats.collapses;
      ++made;
    }
    return made;
  }

  // --- 2. flips and relaxation -----------------------------------------------------------------

  // Flips e when that lifts the worse of its two triangles by more than `margin`, and either
  // its faces are nearly coplanar or (reach > 0) the new diagonal passes within `reach` of the
  // old one.
  bool try_flip(EH e, double margin, double reach) {
    if (mesh.is_boundary(e) || !mesh.is_flip_ok(e)) return false;
    const HH h0 = mesh.halfedge_handle(e, 0), h1 = mesh.halfedge_handle(e, 1);
    const VH a = mesh.to_vertex_handle(h0), b = mesh.to_vertex_handle(h1);
    const VH c = mesh.to_vertex_handle(mesh.next_halfedge_handle(h0));
    const VH d = mesh.to_vertex_handle(mesh.next_halfedge_handle(h1));
    if (c == d || (is_locked(c) && is_locked(d))) return false;  // see locked_links_ok
    const P pa = mesh.point(a), pb = mesh.point(b), pc = mesh.point(c), pd = mesh.point(d);
    // Faces (b, a, c) and (a, b, d) become (c, d, a) and (d, c, b).
    const P n0 = cross_normal(pb, pa, pc), n1 = cross_normal(pa, pb, pd);
    const double l0 = n0.norm(), l1 = n1.norm();
    if (l0 == 0 || l1 == 0) return false;
    const P m0 = cross_normal(pc, pd, pa), m1 = cross_normal(pd, pc, pb);
    if (m0.norm() == 0 || m1.norm() == 0) return false;
    const P n = n0 / l0 + n1 / l1;
    if ((m0 | n) <= 0 || (m1 | n) <= 0) return false;
    // Each new face against its corners' input surface, or no further from it than the worse of
    // the two it replaces.
    const P r0 = area(c) + area(d) + area(a), r1 = area(d) + area(c) + area(b);
    const double s0 = area_sum(c) + area_sum(d) + area_sum(a),
                 s1 = area_sum(d) + area_sum(c) + area_sum(b);
    if (!(faces_input(m0, n0, r0, s0) || faces_input(m0, n1, r0, s0)) ||
        !(faces_input(m1, n0, r1, s1) || faces_input(m1, n1, r1, s1)))
      return false;
    const double before = std::min(quality(pb, pa, pc), quality(pa, pb, pd));
    const double after = std::min(quality(pc, pd, pa), quality(pd, pc, pb));
    if (after <= before + margin) return false;
    const bool flat = (n0 | n1) >= opt.flip_max_angle * l0 * l1;
    if (!flat && !(reach > 0 && segment_gap(pa, pb, pc, pd) <= reach)) return false;
    if (!copies_ok(c, d)) return false;
    const FH fa = mesh.face_handle(h0), fb = mesh.face_handle(h1);
    if (opt.max_error > 0) {
      new_faces.assign({{fa, pc, pd, pa}, {fb, pd, pc, pb}});
      faces_seen.assign({fa.idx(), fb.idx()});
      if (!points_fit_faces(new_faces)) return false;
    }
    mesh.flip(e);
    if (opt.max_error > 0) {
      // OpenMesh keeps both face handles; find which now holds (c, d, a).
      if (!face_has(fa, a)) std::swap(new_faces[0].f, new_faces[1].f);
      reattach(new_faces);
    }
    ++stats.flips;
    return true;
  }

  void flip_pass() {
    for (int round = 0; round < 4; ++round) {
      std::uint64_t flipped = 0;
      for (EH e : mesh.edges())
        if (!mesh.status(e).deleted() && try_flip(e, 1e-3, 0)) ++flipped;
      if (flipped == 0) break;
    }
  }

  // Area-weighted unit normal at v, the mean of its neighbours and the mean squared length of its
  // edges; false for a vertex without a usable fan.
  bool fan(VH v, P& normal, P& centroid, double& edge2) const {
    centroid = P(0, 0, 0);
    normal = P(0, 0, 0);
    edge2 = 0;
    int n = 0;
    for (VH u : mesh.vv_range(v)) {
      centroid += mesh.point(u);
      edge2 += (mesh.point(u) - mesh.point(v)).sqrnorm();
      ++n;
    }
    if (n < 3) return false;
    centroid /= n;
    edge2 /= n;
    for (FH f : mesh.vf_range(v)) {
      auto it = mesh.cfv_iter(f);
      const P a = mesh.point(*it), b = mesh.point(*++it), c = mesh.point(*++it);
      normal += cross_normal(a, b, c);
    }
    const double ln = normal.norm();
    if (!(ln > 0)) return false;
    normal /= ln;
    return true;
  }

  void relax_pass() {
    for (VH v : mesh.vertices()) {
      if (mesh.status(v).deleted() || is_locked(v)) continue;
      P normal, centroid;
      double edge2;
      if (!fan(v, normal, centroid, edge2)) continue;
      const P p = mesh.point(v);
      P d = centroid - p;
      d -= (d | normal) * normal;
      const Quadric& q = quadric(v);
      const P x = onto_quadric(q, p + d, normal);
      const double qx = q(arr(x));
      if (opt.max_error > 0 && qx > opt.max_error * opt.max_error) continue;
      if (qx > q(arr(p)) + opt.relax_tolerance * q.trace() * edge2) continue;
      const double after = worst_after_move(v, v, x);
      if (after < 0 || after < worst_around(v)) continue;
      if (!move_fits(v, x)) continue;
      mesh.set_point(v, x);
      if (opt.max_error > 0) reattach(new_faces);
      ++stats.relaxed;
    }
  }

  // --- 3. cleanup ------------------------------------------------------------------------------

  // Moves v (unlocked) to lift the worst triangle around it: a pattern search along its normal
  // and two tangents, within `reach` of where it started. True when it moved.
  bool optimize_vertex(VH v) {
    if (is_locked(v)) return false;
    P normal, centroid;
    double edge2;
    if (!fan(v, normal, centroid, edge2)) return false;
    const P start = mesh.point(v);
    const double reach = opt.cleanup_reach * std::sqrt(edge2);
    P t1 = normal % P(1, 0, 0);
    if (t1.sqrnorm() < 0.1) t1 = normal % P(0, 1, 0);
    t1.normalize();
    const P t2 = normal % t1;
    const P dirs[6] = {normal, -normal, t1, -t1, t2, -t2};
    const Quadric& q = quadric(v);
    const double bound = opt.max_error > 0 ? opt.max_error * opt.max_error : HUGE_VAL;
    P best = start;
    double best_worst = worst_around(v);
    const double initial = best_worst;
    for (double step = 0.5 * reach; step > reach / 64; step *= 0.5) {
      for (bool improved = true; improved;) {
        improved = false;
        for (const P& d : dirs) {
          const P x = best + step * d;
          if ((x - start).norm() > reach || q(arr(x)) > bound) continue;
          const double w = worst_after_move(v, v, x, FH(), FH(), Flat::Zero);
          if (w > best_worst + 1e-9) {
            best_worst = w;
            best = x;
            improved = true;
          }
        }
      }
    }
    if (best_worst <= initial || !move_fits(v, best)) return false;
    mesh.set_point(v, best);
    if (opt.max_error > 0) reattach(new_faces);
    return true;
  }

  bool fix_face(FH f) {
    HH hs[3];
    P p[3];
    int k = 0;
    for (HH h : mesh.fh_range(f)) {
      hs[k] = h;
      p[k] = mesh.point(mesh.to_vertex_handle(h));
      ++k;
    }
    // Halfedge hs[i] runs from p[i - 1] to p[i].
    double len[3];
    for (int i = 0; i < 3; ++i) len[i] = (p[i] - p[(i + 2) % 3]).sqrnorm();
    int order[3] = {0, 1, 2};
    std::sort(order, order + 3, [&](int a, int b) { return len[a] > len[b]; });
    const double reach = opt.cleanup_reach * std::sqrt(len[order[0]]);
    for (int i : order)
      if (try_flip(mesh.edge_handle(hs[i]), 0.0, reach)) return true;
    const EH shortest = mesh.edge_handle(hs[order[2]]);
    Candidate c;
    if (candidate(shortest, c) && within_error(c)) {
      const VH from = mesh.from_vertex_handle(c.h), to = mesh.to_vertex_handle(c.h);
      const double before = std::min(worst_around(from), worst_around(to));
      if (collapse_worst(c) > before && collapse_fits(c)) {
        apply_collapse(c);
        ++stats.collapses;
        return true;
      }
    }
    bool moved = false;
    for (HH h : hs) moved |= optimize_vertex(mesh.to_vertex_handle(h));
    return moved;
  }

  void cleanup() {
    for (int round = 0; round < 4; ++round) {
      std::uint64_t fixed = 0;
      for (FH f : mesh.faces()) {
        if (mesh.status(f).deleted()) continue;
        auto it = mesh.cfv_iter(f);
        const P a = mesh.point(*it), b = mesh.point(*++it), c = mesh.point(*++it);
        if (quality(a, b, c) >= opt.min_quality) continue;
        if (fix_face(f)) ++fixed;
      }
      stats.cleanup += fixed;
      if (fixed == 0) break;
    }
  }

  // --- output ----------------------------------------------------------------------------------

  Region finish() {
    if (opt.relax_passes > 0) {
      flip_pass();
      for (int i = 0; i < opt.relax_passes; ++i) {
        relax_pass();
        flip_pass();
      }
    }
    cleanup();
    Region out;
    std::vector<std::int64_t> index(mesh.n_vertices(), -1);
    auto keep = [&](int v) {
      if (index[v] < 0) {
        index[v] = static_cast<std::int64_t>(out.positions.size());
        out.positions.push_back(arr(mesh.point(VH(v))));
        out.quadrics.push_back(region.quadrics[v]);
        out.locked.push_back(region.locked[v]);
        if (!region.group.empty()) out.group.push_back(region.group[v]);
        out.id.push_back(region.id[v]);
      }
      return static_cast<std::uint32_t>(index[v]);
    };
    std::vector<std::uint32_t> face_index(mesh.n_faces(), 0);
    for (FH f : mesh.faces()) {
      if (mesh.status(f).deleted()) continue;
      face_index[f.idx()] = static_cast<std::uint32_t>(out.triangles.size());
      Tri t;
      int k = 0;
      for (VH v : mesh.fv_range(f)) t[k++] = keep(v.idx());
      out.triangles.push_back(t);
    }
    const auto linked = static_cast<std::uint32_t>(out.triangles.size());
    for (const Tri& t : unlinked) out.triangles.push_back({keep(t[0]), keep(t[1]), keep(t[2])});
    if (opt.max_error > 0) {
      for (FH f : mesh.faces()) {
        if (mesh.status(f).deleted()) continue;
        for (int i = face_head[f.idx()]; i >= 0; i = pt_next[i]) {
          out.points.push_back(region.points[i]);
          out.point_face.push_back(face_index[f.idx()]);
        }
      }
      for (const auto& [i, u] : fixed_points) {
        out.points.push_back(region.points[i]);
        out.point_face.push_back(linked + static_cast<std::uint32_t>(u));
      }
    }
    return out;
  }

  Region region;  // input; quadrics are updated in place as vertices absorb others
  const RegionOptions opt;
  OMesh mesh;
  std::vector<std::uint8_t> locked;  // the caller's locks plus boundary and unlinked corners
  std::vector<Tri> unlinked;
  std::optional<EdgeHeap> heap;
  std::uint64_t live_faces = 0;
  RegionStats stats;
  mutable std::vector<std::pair<std::int32_t, int>> pairs;
  // The error bound: per face the first of its points, per point the next; points on unlinked
  // faces (index into `unlinked`) never move. Scratch for a change being checked.
  std::vector<int> face_head, pt_next;
  std::vector<std::pair<int, int>> fixed_points;
  std::vector<NewFace> new_faces;
  std::vector<int> faces_seen, gathered, best;
};

RegionSimplifier::RegionSimplifier(Region region, const RegionOptions& options) {
  assert(region.quadrics.size() == region.positions.size());
  assert(region.locked.size() == region.positions.size());
  assert(region.id.size() == region.positions.size());
  impl_ = std::make_unique<Impl>(std::move(region), options);
}
RegionSimplifier::~RegionSimplifier() = default;
RegionSimplifier::RegionSimplifier(RegionSimplifier&&) noexcept = default;
RegionSimplifier& RegionSimplifier::operator=(RegionSimplifier&&) noexcept = default;

std::uint64_t RegionSimplifier::faces() const {
  return impl_->live_faces;
}
void RegionSimplifier::costs(std::vector<double>& out) const {
  impl_->heap->costs(out);
}
std::uint64_t RegionSimplifier::collapse(double max_cost, std::uint64_t max_collapses,
                                         const Progress* progress) {
  return impl_->collapse(max_cost, max_collapses, progress);
}
Region RegionSimplifier::finish() {
  return impl_->finish();
}
const RegionStats& RegionSimplifier::stats() const {
  return impl_->stats;
}

}  // namespace isotile
