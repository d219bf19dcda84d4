// A plane quadric (Garland and Heckbert): the sum of squared distances from a point to a set of
// planes, as a symmetric 4x4 matrix. The simplifier keeps one per vertex, for the input faces the
// vertex stands for, together with those faces' area vectors summed (the matrix is the same for a
// plane and its reverse, so it cannot tell which way the surface faces).
#pragma once

#include <algorithm>
#include <array>

#include "core/volume/volume.h"

namespace isotile {

// Stored as its upper triangle: sum over planes n.x + d = 0 of (n.x + d)^2 = x^T A x + 2 b.x + c.
struct Quadric {
  std::array<double, 10> m{};  // a00 a01 a02 a11 a12 a22 b0 b1 b2 c
  // The input faces' normals times their areas, summed: the direction the surface the vertex
  // stands for faces, area-weighted so that the slivers and specks extraction makes (Marching
  // Cubes around samples equal to the isovalue) barely count. Not part of the distance.
  Vec3d area{0, 0, 0};
  double area_sum = 0;  // their areas summed: |area| / area_sum says how coherently they face

  // The plane n.x + d = 0 (n of unit length), with weight 1.
  static Quadric plane(const Vec3d& n, double d) {
    Quadric q;
    q.m = {n[0] * n[0], n[0] * n[1], n[0] * n[2], n[1] * n[1], n[1] * n[2],
           n[2] * n[2], n[0] * d,    n[1] * d,    n[2] * d,    d * d};
    return q;
  }
  Quadric& operator+=(const Quadric& o) {
    for (int i = 0; i < 10; ++i) m[i] += o.m[i];
    for (int i = 0; i < 3; ++i) area[i] += o.area[i];
    area_sum += o.area_sum;
    return *this;
  }
  Quadric& operator-=(const Quadric& o) {
    for (int i = 0; i < 10; ++i) m[i] -= o.m[i];
    for (int i = 0; i < 3; ++i) area[i] -= o.area[i];
    area_sum -= o.area_sum;
    return *this;
  }
  // The sum of squared distances from x to the planes.
  double operator()(const Vec3d& x) const {
    const auto& a = m;
    const double ax0 = a[0] * x[0] + a[1] * x[1] + a[2] * x[2];
    const double ax1 = a[1] * x[0] + a[3] * x[1] + a[4] * x[2];
    const double ax2 = a[2] * x[0] + a[4] * x[1] + a[5] * x[2];
    const double e =
        x[0] * ax0 + x[1] * ax1 + x[2] * ax2 + 2 * (a[6] * x[0] + a[7] * x[1] + a[8] * x[2]) + a[9];
    return std::max(e, 0.0);  // rounding can take a sum of squares slightly below zero
  }
  double trace() const { return m[0] + m[3] + m[5]; }  // the planes' weights summed
};

}  // namespace isotile
