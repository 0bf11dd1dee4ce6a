!> Upper bounds of a particle's radius function r(u) over cells of directions, for the audit's
!> early-outs (`anm verify`): a sampled surface point y of one particle that lies farther from the
!> other particle's centre than the bound of r there cannot be inside it.
!>
!> The directions are cut by a cube map: each face of the cube [-1, 1]^3 (the directions whose
!> largest component is along its axis k) is cut into nc x nc cells of its gnomonic coordinates
!> a = y_i / |y_k|, b = y_j / |y_k|. Lines of constant a or b are great circles, along which every
!> degree-l part r_l of r is a trigonometric polynomial of degree l in the arc length s, so
!> |d2 r/ds2| <= M2 = sum_l l^2 max|r_l| (Bernstein's inequality), and max|r_l| <= |c_l|
!> sqrt((2l+1)/(4 pi)) (Cauchy-Schwarz and the addition theorem; |c_l| is the norm of the
!> degree-l coefficients in an orthonormal basis). A function with |g''| <= M2 on an arc of length
!> S exceeds the larger of its end values by at most M2 S^2 / 8; an arc inside a cell is no longer
!> than the cell's coordinate width 2/nc (the gnomonic map never shortens lengths), so r over a cell
!> is at most the largest of r at its four corners plus M2 (2/nc)^2 / 4. The table is therefore a
!> bound, not an estimate (to rounding; a relative 1e-12 is added). It is independent of the
!> contact code: only the SH evaluation is shared.
!>
!> A cap of directions (a ball seen from the origin) is bounded by the cells its gnomonic box can
!> touch: within a face, |grad a| <= sqrt(1 + a^2) sqrt(1 + a^2 + b^2) <= sqrt(6) per radian.
!>
!> Usage:
!>     call new_radius_bounds(bounds, shape, 6.0e-3_wp)
!>     if (ly >= bound_at(bounds, y)) ...     ! the point y (|y| = ly) is outside the particle
!>     if (ball_beyond(bounds, c, r)) ...    ! no point of the ball (c, r) is inside the particle
module anm_audit_bounds
   use anm_core_kinds, only: wp, pi
   use anm_sh_expansion, only: sh_expansion_type
   implicit none
   private

   public :: radius_bounds_type, new_radius_bounds, curvature_bound, bound_at, ball_beyond

   !> Cube-map table of upper bounds of r (shape units); immutable after construction.
   type :: radius_bounds_type
      !> Cells per face edge.
      integer :: nc = 0
      !> Upper bound of r over the directions of each cell (nc, nc, 6): face 2k - 1 is +k, 2k is -k.
      real(wp), allocatable :: ub(:, :, :)
      !> The largest bound (a bound of r over all directions).
      real(wp) :: umax = 0.0_wp
   end type radius_bounds_type

   !> Cells per face edge: limits.
   integer, parameter :: min_cells = 8
   !> Most cells per face edge (a table holds at most 6 max_bound_cells**2 bounds).
   integer, parameter, public :: max_bound_cells = 192
   !> sqrt(6): bound of |grad a| of a gnomonic coordinate a over its face (per radian).
   real(wp), parameter :: gnomonic_speed = 2.4494898_wp

contains

   !> M2 = sum_l l^2 |c_l| sqrt((2l+1)/(4 pi)): a bound of |d2r/ds2| along every great circle.
   pure function curvature_bound(shape) result(m2)
      !> Expansion (real form, Pbar_n^m orthonormal with exp(i m phi)).
      type(sh_expansion_type), intent(in) :: shape
      real(wp) :: m2, cl
      integer :: l
      m2 = 0.0_wp
      do l = 1, shape%nmax
         ! real orthonormal coefficients: A_l0, A_lm / sqrt(2), B_lm / sqrt(2)
         cl = shape%a(l, 0)**2 + 0.5_wp * sum(shape%a(l, 1:l)**2 + shape%b(l, 1:l)**2)
         m2 = m2 + real(l, wp)**2 * sqrt(cl * (2 * l + 1) / (4.0_wp * pi))
      end do
   end function curvature_bound

   !> Build the table of `shape`: cells fine enough for a curvature allowance of about `slack`
   !> times the mean radius (8 to 192 cells per face edge).
   pure subroutine new_radius_bounds(self, shape, slack)
      !> Table to build.
      type(radius_bounds_type), intent(out) :: self
      !> Expansion (evaluated to its full degree).
      type(sh_expansion_type), intent(in) :: shape
      !> Curvature allowance relative to the mean radius.
      real(wp), intent(in) :: slack
      real(wp), allocatable :: node(:, :)
      real(wp) :: m2, r0, delta, allowance, v(3)
      integer :: f, k, i, j, ia, ib
      m2 = curvature_bound(shape)
      r0 = max(shape%mean_radius(), tiny(1.0_wp))
      self%nc = max(min_cells, min(max_bound_cells, ceiling(sqrt(m2 / (slack * r0)))))
      delta = 2.0_wp / self%nc
      allowance = m2 * delta**2 / 4.0_wp
      allocate (self%ub(self%nc, self%nc, 6), node(self%nc + 1, self%nc + 1))
      do f = 1, 6
         k = (f + 1) / 2
         i = 1 + modulo(k, 3)
         j = 1 + modulo(k + 1, 3)
         v(k) = merge(1.0_wp, -1.0_wp, mod(f, 2) == 1)
         do ib = 1, self%nc + 1
            do ia = 1, self%nc + 1
               v(i) = -1.0_wp + (ia - 1) * delta
               v(j) = -1.0_wp + (ib - 1) * delta
               node(ia, ib) = shape%radius_dir(v)
            end do
         end do
         do ib = 1, self%nc
            do ia = 1, self%nc
               self%ub(ia, ib, f) = (max(node(ia, ib), node(ia + 1, ib), node(ia, ib + 1), node(ia + 1, ib + 1)) &
                                     + allowance) * (1.0_wp + 1.0e-12_wp)
            end do
         end do
      end do
      self%umax = maxval(self%ub)
   end subroutine new_radius_bounds

   !> The cube-map face of direction y (nonzero): the axis k of its largest component, the two other
   !> axes i, j (cyclic) and the face number f (2k - 1 for +k, 2k for -k).
   pure subroutine cube_face(y, k, i, j, f)
      real(wp), intent(in) :: y(3)
      integer, intent(out) :: k, i, j, f
      if (abs(y(1)) >= abs(y(2)) .and. abs(y(1)) >= abs(y(3))) then
         k = 1
      else if (abs(y(2)) >= abs(y(3))) then
         k = 2
      else
         k = 3
      end if
      i = 1 + modulo(k, 3)
      j = 1 + modulo(k + 1, 3)
      f = 2 * k - merge(1, 0, y(k) >= 0.0_wp)
   end subroutine cube_face

   !> Upper bound of r over the cell holding direction y (nonzero, need not be normalised).
   pure real(wp) function bound_at(self, y) result(bound)
      !> Table.
      type(radius_bounds_type), intent(in) :: self
      !> Direction.
      real(wp), intent(in) :: y(3)
      real(wp) :: scale
      integer :: k, i, j, f, ia, ib
      call cube_face(y, k, i, j, f)
      scale = 0.5_wp * self%nc / abs(y(k))
      ia = min(self%nc, int(y(i) * scale + 0.5_wp * self%nc) + 1)
      ib = min(self%nc, int(y(j) * scale + 0.5_wp * self%nc) + 1)
      bound = self%ub(max(1, ia), max(1, ib), f)
   end function bound_at

   !> True when no point of the ball (c, r) can lie inside the particle: the ball is farther from
   !> the centre than the bound of every cell its cap of directions meets (false, without proof,
   !> when the ball holds the centre or its cap's box leaves the face of c).
   pure logical function ball_beyond(self, c, r) result(out)
      !> Table.
      type(radius_bounds_type), intent(in) :: self
      !> Ball centre and radius (shape units).
      real(wp), intent(in) :: c(3), r
      real(wp) :: lc, x, ta, w0, q, wa, wb, a, b, inv, delta, limit, cosb, ci, cj, ck, am, bm
      integer :: k, i, j, f, ia0, ia1, ib0, ib1, ia, ib
      out = .false.
      lc = norm2(c)
      if (lc <= r) return
      if (lc - r >= self%umax) then
         out = .true.
         return
      end if
      ! every direction of the cap is within alpha = asin(r / lc) <= tan(alpha) of c; along such an
      ! arc the gnomonic coordinates of c's face change by at most gnomonic_speed per radian while it
      ! stays in the face, so a box of half-width w0 inside the face holds the cap; within that box
      ! |grad a| <= sqrt(1 + a^2) sqrt(1 + a^2 + b^2) at its largest |a|, |b| (and alike for b)
      x = r / lc
      ta = x / sqrt(1.0_wp - x * x) * (1.0_wp + 1.0e-12_wp)
      w0 = gnomonic_speed * ta
      call cube_face(c, k, i, j, f)
      inv = 1.0_wp / abs(c(k))
      a = c(i) * inv
      b = c(j) * inv
      if (abs(a) + w0 >= 1.0_wp .or. abs(b) + w0 >= 1.0_wp) return
      q = sqrt(1.0_wp + (abs(a) + w0)**2 + (abs(b) + w0)**2)
      wa = sqrt(1.0_wp + (abs(a) + w0)**2) * q * ta + 1.0e-12_wp
      wb = sqrt(1.0_wp + (abs(b) + w0)**2) * q * ta + 1.0e-12_wp
      delta = 2.0_wp / self%nc
      ia0 = max(1, int((a - wa + 1.0_wp) / delta) + 1)
      ia1 = min(self%nc, int((a + wa + 1.0_wp) / delta) + 1)
      ib0 = max(1, int((b - wb + 1.0_wp) / delta) + 1)
      ib1 = min(self%nc, int((b + wb + 1.0_wp) / delta) + 1)
      ! beyond when every cell of the box that meets the cap has its bound below the ball's nearest
      ! distance (stop at the first that does not); a cell meets the cap only if its centre is within
      ! alpha + delta / sqrt(2) of c (gnomonic distances are at least the angles)
      limit = lc - r
      cosb = cos(asin(x) + delta / sqrt(2.0_wp) * (1.0_wp + 1.0e-9_wp)) - 1.0e-12_wp
      ck = abs(c(k)) / lc
      ci = c(i) / lc
      cj = c(j) / lc
      do ib = ib0, ib1
         bm = -1.0_wp + (ib - 0.5_wp) * delta
         do ia = ia0, ia1
            if (self%ub(ia, ib, f) <= limit) cycle
            am = -1.0_wp + (ia - 0.5_wp) * delta
            if (am * ci + bm * cj + ck >= cosb * sqrt(1.0_wp + am * am + bm * bm)) return
         end do
      end do
      out = .true.
   end function ball_beyond
end module anm_audit_bounds
