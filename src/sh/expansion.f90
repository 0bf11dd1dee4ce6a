!> Real spherical-harmonic expansions r(theta, phi) of star-shaped particle surfaces.
!>
!> The file convention (docs/conventions.md) is r = Re sum_{n,m} a_nm Y_n^m with complex orthonormal
!> Y_n^m (Condon-Shortley phase). Internally the expansion is stored in real form,
!>     r = sum_n sum_{m=0..n} Pbar_n^m(cos theta) (A_nm cos(m phi) + B_nm sin(m phi)),
!> with A_n0 = Re a_n0 and, for m > 0, A_nm = Re a_nm + (-1)^m Re a_{n,-m},
!> B_nm = -Im a_nm + (-1)^m Im a_{n,-m}. For the conjugate-symmetric files NIST writes
!> (a_{n,-m} = (-1)^m conj a_nm) this is A = 2 Re a_nm, B = -2 Im a_nm.
!>
!> Evaluation at a single direction sums over n per order m (a fused column recursion, no
!> storage), then over m with cos(m phi), sin(m phi) from the Chebyshev recurrence: no
!> trigonometric call per term.
!>
!> Usage:
!>     call new_sh_expansion(shape, coeff, nmax)     ! coeff(0:nmax, -nmax:nmax) complex
!>     r = shape%radius_dir([ux, uy, uz])           ! unit direction, body frame
!>     call shape%point(theta, phi, r, r_theta, r_phi_sin)
module anm_sh_expansion
   use anm_core_kinds, only: wp
   use anm_sh_legendre, only: legendre_table_type, new_legendre_table, legendre_values, &
      & legendre_theta_derivatives, packed_size
   use anm_sh_kernel, only: sh_sum, sh_sum_slope, sh_sum_surface
   implicit none
   private

   public :: sh_expansion_type, new_sh_expansion, new_sh_expansion_real, sh_truncate, &
      & sh_to_complex, sh_from_rows, sh_to_rows, surface_normal

   !> A real SH expansion of degree nmax (immutable after construction; safe to share between
   !> threads).
   type :: sh_expansion_type
      !> Highest degree stored.
      integer :: nmax = -1
      !> Cosine coefficients A(n, m), 0 <= m <= n <= nmax (entries with m > n are zero).
      real(wp), allocatable :: a(:, :)
      !> Sine coefficients B(n, m).
      real(wp), allocatable :: b(:, :)
      !> Legendre recursion table of degree nmax + 1 (for values and derivatives).
      type(legendre_table_type) :: table
   contains
      !> r along a unit direction (body frame).
      procedure :: radius_dir
      !> r at (theta, phi).
      procedure :: radius
      !> r and its angular derivatives at (theta, phi).
      procedure :: point
      !> r and the norm of its surface gradient along a unit direction (no allocation).
      procedure :: radius_slope
      !> r and its surface gradient (a tangent 3-vector) along a direction
      procedure :: radius_gradient
      !> r, its surface gradient and a bound of its Hessian along a direction (no allocation).
      procedure :: radius_hessian
      !> Mean radius a_00 / (2 sqrt(pi)).
      procedure :: mean_radius
   end type sh_expansion_type

contains

   !> Build an expansion from complex coefficients c(n, m), n = 0..nmax, m = -n..n
   !> (entries with |m| > n are ignored).
   pure subroutine new_sh_expansion(self, coeff, nmax)
      !> Expansion to build.
      type(sh_expansion_type), intent(out) :: self
      !> Complex coefficients a_nm, dimension (0:nmax, -nmax:nmax).
      complex(wp), intent(in) :: coeff(0:, -nmax:)
      !> Highest degree.
      integer, intent(in) :: nmax
      real(wp), allocatable :: a(:, :), b(:, :)
      integer :: n, m
      real(wp) :: sgn

      allocate (a(0:nmax, 0:nmax), b(0:nmax, 0:nmax))
      a = 0.0_wp
      b = 0.0_wp
      do n = 0, nmax
         a(n, 0) = real(coeff(n, 0), wp)
         do m = 1, n
            sgn = merge(-1.0_wp, 1.0_wp, mod(m, 2) == 1)
            a(n, m) = real(coeff(n, m), wp) + sgn * real(coeff(n, -m), wp)
            b(n, m) = -aimag(coeff(n, m)) + sgn * aimag(coeff(n, -m))
         end do
      end do
      call new_sh_expansion_real(self, a, b)
   end subroutine new_sh_expansion

   !> Build an expansion from real-form coefficients A(0:nmax, 0:nmax), B(0:nmax, 0:nmax).
   pure subroutine new_sh_expansion_real(self, a, b)
      !> Expansion to build.
      type(sh_expansion_type), intent(out) :: self
      !> Cosine and sine coefficients indexed (n, m).
      real(wp), intent(in) :: a(0:, 0:), b(0:, 0:)
      integer :: n, m

      self%nmax = ubound(a, 1)
      allocate (self%a(0:self%nmax, 0:self%nmax), self%b(0:self%nmax, 0:self%nmax))
      self%a = 0.0_wp
      self%b = 0.0_wp
      do m = 0, self%nmax
         do n = m, self%nmax
            self%a(n, m) = a(n, m)
            if (m > 0) self%b(n, m) = b(n, m)
         end do
      end do
      self%table = new_legendre_table(self%nmax + 1)
   end subroutine new_sh_expansion_real

   !> Copy of `shape` truncated to degree nused (nused >= nmax returns a full copy).
   pure function sh_truncate(shape, nused) result(trunc)
      !> Full expansion.
      type(sh_expansion_type), intent(in) :: shape
      !> Degree to keep.
      integer, intent(in) :: nused
      type(sh_expansion_type) :: trunc
      integer :: nu
      nu = max(0, min(nused, shape%nmax))
      call new_sh_expansion_real(trunc, shape%a(0:nu, 0:nu), shape%b(0:nu, 0:nu))
   end function sh_truncate

   !> Complex coefficients (conjugate-symmetric form) in the NIST layout c(0:nmax, -nmax:nmax).
   pure function sh_to_complex(shape) result(coeff)
      !> Expansion.
      type(sh_expansion_type), intent(in) :: shape
      complex(wp), allocatable :: coeff(:, :)
      integer :: n, m
      real(wp) :: sgn
      allocate (coeff(0:shape%nmax, -shape%nmax:shape%nmax))
      coeff = (0.0_wp, 0.0_wp)
      do n = 0, shape%nmax
         coeff(n, 0) = cmplx(shape%a(n, 0), 0.0_wp, wp)
         do m = 1, n
            sgn = merge(-1.0_wp, 1.0_wp, mod(m, 2) == 1)
            coeff(n, m) = cmplx(0.5_wp * shape%a(n, m), -0.5_wp * shape%b(n, m), wp)
            coeff(n, -m) = sgn * conjg(coeff(n, m))
         end do
      end do
   end function sh_to_complex

   !> Expansion of degree nmax from coefficient rows in the NIST line order (n = 0.., m = n..-n):
   !> rows(1, k) = Re a_nm, rows(2, k) = Im a_nm, k = n^2 + n - m + 1 (the model file's layout).
   pure function sh_from_rows(rows, nmax) result(shape)
      !> Coefficient rows, (2, >= (nmax+1)^2).
      real(wp), intent(in) :: rows(:, :)
      !> Highest degree.
      integer, intent(in) :: nmax
      type(sh_expansion_type) :: shape
      complex(wp) :: c(0:nmax, -nmax:nmax)
      integer :: n, m
      c = (0.0_wp, 0.0_wp)
      do n = 0, nmax
         do m = -n, n
            c(n, m) = cmplx(rows(1, n * n + n - m + 1), rows(2, n * n + n - m + 1), wp)
         end do
      end do
      call new_sh_expansion(shape, c, nmax)
   end function sh_from_rows

   !> Coefficient rows in the NIST line order (the inverse of sh_from_rows), (2, (nmax+1)^2).
   pure function sh_to_rows(shape) result(rows)
      !> Expansion.
      type(sh_expansion_type), intent(in) :: shape
      real(wp), allocatable :: rows(:, :)
      complex(wp), allocatable :: c(:, :)
      integer :: n, m, k
      allocate (c(0:shape%nmax, -shape%nmax:shape%nmax), rows(2, (shape%nmax + 1)**2))
      c(:, :) = sh_to_complex(shape)
      do n = 0, shape%nmax
         do m = n, -n, -1
            k = n * n + n - m + 1
            rows(:, k) = [real(c(n, m), wp), aimag(c(n, m))]
         end do
      end do
   end function sh_to_rows

   !> Mean radius over the sphere, a_00 / (2 sqrt(pi)).
   pure function mean_radius(self) result(rbar)
      !> Expansion.
      class(sh_expansion_type), intent(in) :: self
      real(wp) :: rbar
      rbar = self%a(0, 0) * 0.5_wp / sqrt(acos(-1.0_wp))
   end function mean_radius

   !> r along the unit direction u = (sin t cos p, sin t sin p, cos t) in the body frame.
   !> This is the contact-test hot path: a fused recursion of O(nmax^2) multiply-adds.
   pure function radius_dir(self, u) result(r)
      !> Expansion.
      class(sh_expansion_type), intent(in) :: self
      !> Unit direction (need not be exactly normalised; it is normalised here).
      real(wp), intent(in) :: u(3)
      real(wp) :: r
      real(wp) :: rho, len, x, s, cp, sp
      len = sqrt(u(1)**2 + u(2)**2 + u(3)**2)
      rho = sqrt(u(1)**2 + u(2)**2)
      x = u(3) / len
      s = rho / len
      if (rho > 0.0_wp) then
         cp = u(1) / rho
         sp = u(2) / rho
      else
         cp = 1.0_wp
         sp = 0.0_wp
      end if
      r = radius_xs(self, x, s, cp, sp)
   end function radius_dir

   !> r at polar angle theta and azimuth phi (radians).
   pure function radius(self, theta, phi) result(r)
      !> Expansion.
      class(sh_expansion_type), intent(in) :: self
      !> Polar angle and azimuth.
      real(wp), intent(in) :: theta, phi
      real(wp) :: r
      r = radius_xs(self, cos(theta), sin(theta), cos(phi), sin(phi))
   end function radius

   !> Fused evaluation from cos/sin of theta and phi (`anm_sh_kernel`).
   pure function radius_xs(self, x, s, cp, sp) result(r)
      type(sh_expansion_type), intent(in) :: self
      real(wp), intent(in) :: x, s, cp, sp
      real(wp) :: r
      r = sh_sum(self%table, self%a, self%b, self%nmax, x, s, cp, sp)
   end function radius_xs

   !> r and |grad r| = sqrt(r_theta^2 + r_phi_sin^2) along the direction u (body frame, need not be
   !> normalised) by one fused column recursion per order, without allocation. The theta
   !> derivative uses sin(theta) dPbar_n^m/dtheta = n x Pbar_n^m - f_nm Pbar_{n-1}^m with
   !> f_nm = (2n+1)/ca, so u must not be a pole (sin(theta) > 0); the relative rounding error grows
   !> like epsilon/sin(theta).
   pure subroutine radius_slope(self, u, r, slope)
      !> Expansion.
      class(sh_expansion_type), intent(in) :: self
      !> Direction, not along the z axis.
      real(wp), intent(in) :: u(3)
      !> r(u).
      real(wp), intent(out) :: r
      !> |grad r| at u (per radian).
      real(wp), intent(out) :: slope
      real(wp) :: x, s, cp, sp, rt, rp
      call off_pole(u, x, s, cp, sp)
      call sh_sum_slope(self%table, self%a, self%b, self%nmax, x, s, cp, sp, r, rt, rp)
      slope = sqrt(rt**2 + rp**2) / s
   end subroutine radius_slope

   !> r and its surface gradient g = r_theta e_theta + (r_phi / sin theta) e_phi (a tangent
   !> 3-vector, per radian) along the direction u (body frame, need not be normalised, not a
   !> pole), by the fused recursion of `radius_slope`. The outward normal of the surface r(u) u
   !> there is along r u - g.
   pure subroutine radius_gradient(self, u, r, g)
      !> Expansion.
      class(sh_expansion_type), intent(in) :: self
      !> Direction, not along the z axis.
      real(wp), intent(in) :: u(3)
      !> r(u) and the surface gradient.
      real(wp), intent(out) :: r, g(3)
      real(wp) :: x, s, cp, sp, rt, rp
      call off_pole(u, x, s, cp, sp)
      call sh_sum_slope(self%table, self%a, self%b, self%nmax, x, s, cp, sp, r, rt, rp)
      g = (rt / s) * [x * cp, x * sp, -s] + (rp / s) * [-sp, cp, 0.0_wp]
   end subroutine radius_gradient

   !> cos and sin of the polar angle and of the azimuth of a direction u off the z axis (need not
   !> be normalised).
   pure subroutine off_pole(u, x, s, cp, sp)
      real(wp), intent(in) :: u(3)
      real(wp), intent(out) :: x, s, cp, sp
      real(wp) :: len, rho
      len = sqrt(u(1)**2 + u(2)**2 + u(3)**2)
      rho = sqrt(u(1)**2 + u(2)**2)
      x = u(3) / len
      s = rho / len
      cp = u(1) / rho
      sp = u(2) / rho
   end subroutine off_pole

   !> r, its surface gradient g (tangent 3-vector: r_theta e_theta + (r_phi / sin theta) e_phi)
   !> and hmax, the largest |eigenvalue| of its covariant Hessian on the unit sphere (so that, at
   !> u itself, |d2r/ds2| <= hmax along every great circle through u), at the direction u (body
   !> frame, need not be normalised, not a pole). The outward normal of the surface r(u) u there
   !> is along r u - g. One fused evaluation (`sh_sum_surface`, the table's e_nm), no allocation.
   !> Used by the contact distance test's thin boxes (anm_contact_overlap).
   pure subroutine radius_hessian(self, u, r, g, hmax)
      !> Expansion.
      class(sh_expansion_type), intent(in) :: self
      !> Direction, not along the z axis.
      real(wp), intent(in) :: u(3)
      !> r(u), gradient, largest |eigenvalue| of the Hessian.
      real(wp), intent(out) :: r, g(3), hmax
      real(wp) :: ct, st, cp, sp, f(6), cot, h11, h12, h22
      call off_pole(u, ct, st, cp, sp)
      ! r, r_t, r_p, r_tt, r_tp, r_pp (plain derivatives in theta and phi)
      call sh_sum_surface(self%table, self%a, self%b, self%table%enm, self%nmax, ct, st, cp, sp, f)
      r = f(1)
      g = f(2) * [ct * cp, ct * sp, -st] + (f(3) / st) * [-sp, cp, 0.0_wp]
      ! covariant Hessian in the frame (e_theta, e_phi)
      cot = ct / st
      h11 = f(4)
      h12 = (f(5) - cot * f(3)) / st
      h22 = f(6) / st**2 + cot * f(2)
      hmax = abs(0.5_wp * (h11 + h22)) + sqrt((0.5_wp * (h11 - h22))**2 + h12**2)
   end subroutine radius_hessian

   !> r and its angular derivatives at (theta, phi): r_theta = dr/dtheta and
   !> r_phi_sin = (dr/dphi) / sin(theta), the latter finite at the poles.
   pure subroutine point(self, theta, phi, r, r_theta, r_phi_sin)
      !> Expansion.
      class(sh_expansion_type), intent(in) :: self
      !> Polar angle and azimuth (radians).
      real(wp), intent(in) :: theta, phi
      !> Radius.
      real(wp), intent(out) :: r
      !> dr/dtheta.
      real(wp), intent(out) :: r_theta
      !> (dr/dphi) / sin(theta).
      real(wp), intent(out) :: r_phi_sin
      real(wp), allocatable :: p(:), dp(:), mps(:)
      integer, allocatable :: idx_out(:)
      integer :: n, m, k, nmax
      real(wp) :: cm, sm

      nmax = self%nmax
      allocate (p(packed_size(nmax + 1)), dp(packed_size(nmax)), mps(packed_size(nmax)))
      allocate (idx_out(0:nmax))
      k = 1
      do m = 0, nmax
         idx_out(m) = k
         k = k + nmax - m + 1
      end do
      call legendre_values(self%table, cos(theta), p, sin(theta))
      call legendre_theta_derivatives(self%table, p, nmax, idx_out, dp, mps)
      r = 0.0_wp
      r_theta = 0.0_wp
      r_phi_sin = 0.0_wp
      do m = 0, nmax
         cm = cos(m * phi)
         sm = sin(m * phi)
         do n = m, nmax
            r = r + p(self%table%idx(m) + n - m) * (self%a(n, m) * cm + self%b(n, m) * sm)
            r_theta = r_theta + dp(idx_out(m) + n - m) * (self%a(n, m) * cm + self%b(n, m) * sm)
            r_phi_sin = r_phi_sin + mps(idx_out(m) + n - m) * (self%b(n, m) * cm - self%a(n, m) * sm)
         end do
      end do
   end subroutine point

   !> Outward unit normal (Cartesian, body frame) of the surface r(theta, phi) from r and its
   !> angular derivatives: n ~ r rhat - r_theta thetahat - r_phi_sin phihat.
   pure function surface_normal(theta, phi, r, r_theta, r_phi_sin) result(nrm)
      !> Direction of the surface point.
      real(wp), intent(in) :: theta, phi
      !> r, dr/dtheta, (dr/dphi)/sin(theta) at that direction.
      real(wp), intent(in) :: r, r_theta, r_phi_sin
      real(wp) :: nrm(3)
      real(wp) :: st, ct, sp, cp, rh(3), th(3), ph(3)
      st = sin(theta)
      ct = cos(theta)
      sp = sin(phi)
      cp = cos(phi)
      rh = [st * cp, st * sp, ct]
      th = [ct * cp, ct * sp, -st]
      ph = [-sp, cp, 0.0_wp]
      nrm = r * rh - r_theta * th - r_phi_sin * ph
      nrm = nrm / sqrt(sum(nrm**2))
   end function surface_normal
end module anm_sh_expansion
