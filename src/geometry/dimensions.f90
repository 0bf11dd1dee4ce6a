!> Length, width and thickness of a particle (definitions in docs/conventions.md):
!>   L: the longest surface-point-to-surface-point distance (the diameter of the body);
!>   W: the longest surface-point-to-surface-point distance whose direction is perpendicular to L;
!>   T: the longest such distance whose direction is perpendicular to both L and W.
!> W and T are chords: for a direction d, the longest distance between two surface points on a
!> line parallel to d is the span between the line's first and last crossing of the surface.
!>
!> Method. L: farthest-point ("double normal") iterations on a dense surface sample from several
!> starts, then a continuous refinement of both end points by tangent-plane compass search.
!> W: for 180 directions d perpendicular to L, the surface sample is binned on the plane
!> perpendicular to d and the span of d . x is taken per bin; the best (d, line) is then refined
!> with exact chords (line-surface crossings by marching and bisection) by a compass search in the
!> direction angle and the line offset. T: the same with d fixed to L x W. With certified radius
!> bounds per direction (`bound`, anm_geometry_radial_bound) the marches skip the evaluation of r
!> at points those bounds put outside: the same crossings, several times fewer evaluations.
!>
!> Usage:
!>     call particle_dimensions(shape, grid, length, width, thickness, dir_l, dir_w, dir_t)
module anm_geometry_dimensions
   use anm_core_kinds, only: wp, pi
   use anm_sh_expansion, only: sh_expansion_type
   use anm_sh_grid, only: sh_grid_type, sh_synthesize
   use anm_geometry_sphere_search, only: maximize_direction
   use anm_geometry_radial_bound, only: radial_bound_type, surely_outside
   implicit none
   private

   public :: particle_dimensions, chord_span

contains

   !> L, W, T and their unit directions (body frame).
   subroutine particle_dimensions(shape, grid, length, width, thickness, dir_l, dir_w, dir_t, bound)
      !> Particle (already truncated to the order wanted).
      type(sh_expansion_type), intent(in) :: shape
      !> Dense grid for the surface sample.
      type(sh_grid_type), intent(in) :: grid
      !> Length, width, thickness.
      real(wp), intent(out) :: length, width, thickness
      !> Directions of L, W, T (unit, mutually perpendicular).
      real(wp), intent(out) :: dir_l(3), dir_w(3), dir_t(3)
      !> Certified radius bounds of `shape` (the same results, faster chord marches).
      type(radial_bound_type), intent(in), optional :: bound
      real(wp), allocatable :: pts(:, :), r(:, :)
      real(wp) :: rmax, e1(3), e2(3), d(3), best, val, alpha, best_alpha, o1, o2, best_o(2)
      integer :: nt, np, npts, i, j, k, ia
      integer, parameter :: nalpha = 180

      nt = grid%sphere%ntheta
      np = grid%sphere%nphi
      allocate (r(nt, np))
      call sh_synthesize(grid, shape, r)
      npts = nt * np
      allocate (pts(3, npts))
      k = 0
      do j = 1, np
         do i = 1, nt
            k = k + 1
            pts(:, k) = r(i, j) * [grid%sphere%sint(i) * grid%trig(2, j), &
                                   grid%sphere%sint(i) * grid%trig(grid%lmax + 2, j), grid%sphere%x(i)]
         end do
      end do
      rmax = maxval(r)

      call diameter(shape, pts, length, dir_l)

      ! width: directions d = cos(a) e1 + sin(a) e2 perpendicular to L
      call perpendicular_pair(dir_l, e1, e2)
      best = -1.0_wp
      best_alpha = 0.0_wp
      best_o = 0.0_wp
      do ia = 0, nalpha - 1
         alpha = pi * ia / real(nalpha, wp)
         d = cos(alpha) * e1 + sin(alpha) * e2
         call binned_span(pts, d, dir_l, rmax, val, o1, o2)
         if (val > best) then
            best = val
            best_alpha = alpha
            best_o = [o1, o2]
         end if
      end do
      call refine_chord(shape, rmax, dir_l, e1, e2, best_alpha, best_o, .true., best, bound)
      width = best
      dir_w = cos(best_alpha) * e1 + sin(best_alpha) * e2
      dir_t = cross(dir_l, dir_w)
      dir_t = dir_t / norm2(dir_t)

      ! thickness: chords parallel to dir_t
      call binned_span(pts, dir_t, dir_l, rmax, best, o1, o2)
      best_o = [o1, o2]
      alpha = 0.0_wp
      call refine_chord(shape, rmax, dir_l, dir_t, dir_w, alpha, best_o, .false., best, bound)
      thickness = best
   end subroutine particle_dimensions

   include "anm_cross.inc"

   pure subroutine perpendicular_pair(u, e1, e2)
      real(wp), intent(in) :: u(3)
      real(wp), intent(out) :: e1(3), e2(3)
      real(wp) :: a(3)
      if (abs(u(1)) < 0.6_wp) then
         a = [1.0_wp, 0.0_wp, 0.0_wp]
      else
         a = [0.0_wp, 1.0_wp, 0.0_wp]
      end if
      e1 = a - dot_product(a, u) * u
      e1 = e1 / norm2(e1)
      e2 = cross(u, e1)
   end subroutine perpendicular_pair

   !> Diameter of the body. On the sample: double-normal iterations give a lower bound D0; a
   !> point can end a longer chord only if |p| + max|q| >= D0, so the exact sample diameter is the
   !> largest distance among those candidate points. The best pair is then refined continuously,
   !> alternating the two end points.
   subroutine diameter(shape, pts, length, dir_l)
      type(sh_expansion_type), intent(in) :: shape
      real(wp), intent(in) :: pts(:, :)
      real(wp), intent(out) :: length, dir_l(3)
      integer :: ip, iq, it, k, i, j, ncand
      real(wp) :: dbest, d2, u1(3), u2(3), q(3), f1, f2, fold, rmax, d0
      integer :: best_p, best_q
      integer, allocatable :: cand(:)
      real(wp), allocatable :: rad(:)

      rad = sqrt(sum(pts**2, dim=1))
      rmax = maxval(rad)
      ip = maxloc(rad, dim=1)
      do it = 1, 20
         iq = farthest(pts, pts(:, ip))
         k = farthest(pts, pts(:, iq))
         if (k == ip) exit
         ip = k
      end do
      d0 = norm2(pts(:, ip) - pts(:, iq))
      cand = pack([(i, i=1, size(pts, 2))], rad >= d0 - rmax - 1.0e-12_wp * rmax)
      ncand = size(cand)
      ! visit candidates by decreasing radius: |p - q| <= |p| + |q|, so once the two radii cannot
      ! beat the best distance the remaining pairs are skipped (near-spheres end at once)
      call sort_by_radius(cand, rad)
      dbest = d0**2
      best_p = ip
      best_q = iq
      do i = 1, ncand
         if ((rad(cand(i)) + rad(cand(min(i + 1, ncand))))**2 <= dbest) exit
         do j = i + 1, ncand
            if ((rad(cand(i)) + rad(cand(j)))**2 <= dbest) exit
            d2 = (pts(1, cand(i)) - pts(1, cand(j)))**2 + (pts(2, cand(i)) - pts(2, cand(j)))**2 &
                 + (pts(3, cand(i)) - pts(3, cand(j)))**2
            if (d2 > dbest) then
               dbest = d2
               best_p = cand(i)
               best_q = cand(j)
            end if
         end do
      end do
      u1 = pts(:, best_p) / norm2(pts(:, best_p))
      u2 = pts(:, best_q) / norm2(pts(:, best_q))
      fold = sqrt(dbest)
      f2 = fold
      do it = 1, 50
         q = shape%radius_dir(u2) * u2
         call maximize_direction(dist_from_q, u1, 0.01_wp, 1.0e-10_wp, f1)
         q = shape%radius_dir(u1) * u1
         call maximize_direction(dist_from_q, u2, 0.01_wp, 1.0e-10_wp, f2)
         if (f2 - fold <= 1.0e-13_wp * f2) exit
         fold = f2
      end do
      length = f2
      dir_l = shape%radius_dir(u1) * u1 - shape%radius_dir(u2) * u2
      dir_l = dir_l / norm2(dir_l)
   contains
      function dist_from_q(uu) result(f)
         real(wp), intent(in) :: uu(3)
         real(wp) :: f
         f = norm2(shape%radius_dir(uu) * uu - q)
      end function dist_from_q
   end subroutine diameter

   !> Sort indices by decreasing rad(idx) (heap sort, O(n log n)).
   pure subroutine sort_by_radius(idx, rad)
      integer, intent(inout) :: idx(:)
      real(wp), intent(in) :: rad(:)
      integer :: n, i, tmp
      n = size(idx)
      do i = n / 2, 1, -1
         call sift(idx, rad, i, n)
      end do
      do i = n, 2, -1
         tmp = idx(1)
         idx(1) = idx(i)
         idx(i) = tmp
         call sift(idx, rad, 1, i - 1)
      end do
   contains
      pure subroutine sift(idx, rad, start, last)
         integer, intent(inout) :: idx(:)
         real(wp), intent(in) :: rad(:)
         integer, intent(in) :: start, last
         integer :: root, child, t
         root = start
         do while (2 * root <= last)
            child = 2 * root
            ! min-heap on rad gives a decreasing order after the sort
            if (child < last) then
               if (rad(idx(child + 1)) < rad(idx(child))) child = child + 1
            end if
            if (rad(idx(child)) < rad(idx(root))) then
               t = idx(root)
               idx(root) = idx(child)
               idx(child) = t
               root = child
            else
               return
            end if
         end do
      end subroutine sift
   end subroutine sort_by_radius

   pure function farthest(pts, p) result(k)
      real(wp), intent(in) :: pts(:, :), p(3)
      integer :: k, i
      real(wp) :: dmax, d
      dmax = -1.0_wp
      k = 1
      do i = 1, size(pts, 2)
         d = (pts(1, i) - p(1))**2 + (pts(2, i) - p(2))**2 + (pts(3, i) - p(3))**2
         if (d > dmax) then
            dmax = d
            k = i
         end if
      end do
   end function farthest

   !> Largest span of d . x over bins of the plane perpendicular to d (coordinates along `a` and
   !> d x a); returns the span and the bin centre (o1, o2) of the best line.
   pure subroutine binned_span(pts, d, a, rmax, span, o1, o2)
      real(wp), intent(in) :: pts(:, :), d(3), a(3), rmax
      real(wp), intent(out) :: span, o1, o2
      integer, parameter :: nb = 64, blk = 512
      real(wp) :: smin(nb, nb), smax(nb, nb), b(3), h, s(blk), c1, c2
      integer :: i, i0, k, n, i1(blk), i2(blk), loc(2)
      b = cross(d, a)
      h = 2.0_wp * rmax / nb
      smin = huge(1.0_wp)
      smax = -huge(1.0_wp)
      ! a block of points projected (a loop the compiler vectorises), then binned
      do i0 = 0, size(pts, 2) - 1, blk
         n = min(blk, size(pts, 2) - i0)
         do k = 1, n
            i = i0 + k
            c1 = dot_product(pts(:, i), a)
            c2 = dot_product(pts(:, i), b)
            s(k) = dot_product(pts(:, i), d)
            i1(k) = min(nb, max(1, 1 + int((c1 + rmax) / h)))
            i2(k) = min(nb, max(1, 1 + int((c2 + rmax) / h)))
         end do
         do k = 1, n
            smin(i1(k), i2(k)) = min(smin(i1(k), i2(k)), s(k))
            smax(i1(k), i2(k)) = max(smax(i1(k), i2(k)), s(k))
         end do
      end do
      where (smax < smin)
         smax = 0.0_wp
         smin = 0.0_wp
      end where
      loc = maxloc(smax - smin)
      span = smax(loc(1), loc(2)) - smin(loc(1), loc(2))
      o1 = -rmax + (loc(1) - 0.5_wp) * h
      o2 = -rmax + (loc(2) - 0.5_wp) * h
   end subroutine binned_span

   !> Refine a chord: maximise chord_span over the line offset (o1 along a, o2 along d x a) and,
   !> when `rotate`, the angle alpha of d = cos(alpha) e1 + sin(alpha) e2.
   subroutine refine_chord(shape, rmax, a, e1, e2, alpha, o, rotate, span, bound)
      type(sh_expansion_type), intent(in) :: shape
      real(wp), intent(in) :: rmax, a(3), e1(3), e2(3)
      real(wp), intent(inout) :: alpha, o(2)
      logical, intent(in) :: rotate
      real(wp), intent(inout) :: span
      type(radial_bound_type), intent(in), optional :: bound
      real(wp) :: h, ha, cand(3), fc, best(3), fbest, x(3)
      integer :: k, nvar, iter
      real(wp), parameter :: dirs(3, 6) = reshape([1.0_wp, 0.0_wp, 0.0_wp, -1.0_wp, 0.0_wp, 0.0_wp, &
                                                   0.0_wp, 1.0_wp, 0.0_wp, 0.0_wp, -1.0_wp, 0.0_wp, &
                                                   0.0_wp, 0.0_wp, 1.0_wp, 0.0_wp, 0.0_wp, -1.0_wp], [3, 6])
      nvar = merge(6, 4, rotate)
      x = [o(1), o(2), alpha]
      fbest = eval(x)
      h = rmax / 32.0_wp
      ha = pi / 180.0_wp
      do iter = 1, 2000
         if (h < 1.0e-9_wp * rmax) exit
         best = x
         fc = fbest
         do k = 1, nvar
            cand = x + [h * dirs(1, k), h * dirs(2, k), ha * dirs(3, k)]
            fc = eval(cand)
            if (fc > fbest) then
               fbest = fc
               best = cand
            end if
         end do
         if (all(best == x)) then
            h = 0.5_wp * h
            ha = 0.5_wp * ha
         else
            x = best
         end if
      end do
      o = x(1:2)
      alpha = x(3)
      span = max(span, fbest)
   contains
      function eval(v) result(f)
         real(wp), intent(in) :: v(3)
         real(wp) :: f, d(3), b(3)
         if (rotate) then
            d = cos(v(3)) * e1 + sin(v(3)) * e2
         else
            d = e1
         end if
         b = cross(d, a)
         f = chord_span(shape, v(1) * a + v(2) * b, d, rmax, bound)
      end function eval
   end subroutine refine_chord

   !> Distance between the first and last crossing of the surface by the line o + s d
   !> (o perpendicular to the unit vector d); 0 if the line misses the body. Crossings are found
   !> by marching inward from |s| = sqrt(rmax^2 - |o|^2) in steps of rmax/400, then bisection.
   function chord_span(shape, o, d, rmax, bound) result(span)
      !> Particle.
      type(sh_expansion_type), intent(in) :: shape
      !> Line offset (perpendicular to d) and unit direction.
      real(wp), intent(in) :: o(3), d(3)
      !> Bound on the radius of the particle.
      real(wp), intent(in) :: rmax
      !> Certified radius bounds per direction: points beyond them are outside without evaluating
      !> r (the same result).
      type(radial_bound_type), intent(in), optional :: bound
      real(wp) :: span
      real(wp) :: s0, smax, smin, step, a, b, m
      integer :: k, it
      real(wp) :: rr

      rr = rmax * 1.0001_wp
      if (sum(o**2) >= rr * rr) then
         span = 0.0_wp
         return
      end if
      s0 = sqrt(rr * rr - sum(o**2))
      step = rmax / 400.0_wp
      ! last crossing: march down from +s0
      smax = -huge(1.0_wp)
      a = s0
      do k = 1, ceiling(2.0_wp * s0 / step) + 1
         b = a - step
         if (b < -s0) b = -s0
         if (inside(b)) then
            do it = 1, 60
               m = 0.5_wp * (a + b)
               if (inside(m)) then
                  b = m
               else
                  a = m
               end if
               if (a - b < 1.0e-12_wp * rmax) exit
            end do
            smax = b
            exit
         end if
         a = b
         if (a <= -s0) exit
      end do
      if (smax == -huge(1.0_wp)) then
         span = 0.0_wp
         return
      end if
      a = -s0
      smin = smax
      do k = 1, ceiling(2.0_wp * s0 / step) + 1
         b = a + step
         if (b > smax) b = smax
         if (inside(b)) then
            do it = 1, 60
               m = 0.5_wp * (a + b)
               if (inside(m)) then
                  b = m
               else
                  a = m
               end if
               if (b - a < 1.0e-12_wp * rmax) exit
            end do
            smin = b
            exit
         end if
         a = b
      end do
      span = smax - smin
   contains
      logical function inside(s)
         real(wp), intent(in) :: s
         real(wp) :: p(3), len
         p = o + s * d
         len = norm2(p)
         if (len == 0.0_wp) then
            inside = .true.
         else
            inside = .true.
            if (present(bound)) inside = .not. surely_outside(bound, p, len)
            if (inside) inside = len <= shape%radius_dir(p / len)
         end if
      end function inside
   end function chord_span
end module anm_geometry_dimensions
