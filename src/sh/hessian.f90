!> Second derivatives of a spherical-harmonic surface at one direction: r, its surface gradient
!> and a bound of its Hessian, for the thin boxes of the contact distance test
!> (anm_contact_overlap, `surfaces_within`).
!>
!> Usage:
!>     call radius_hessian(shape, u, r, g, hmax)
!>     ! at u, |d2r/ds2| <= hmax along every great circle through u; the surface normal is along r u - g
module anm_sh_hessian
   use anm_core_kinds, only: wp
   use anm_sh_expansion, only: sh_expansion_type
   use anm_sh_kernel, only: sh_sum_surface
   implicit none
   private

   public :: radius_hessian

contains

   !> r, its surface gradient g (tangent 3-vector: r_theta e_theta + (r_phi / sin theta) e_phi)
   !> and hmax, the largest |eigenvalue| of its covariant Hessian on the unit sphere (so that, at
   !> u itself, |d2r/ds2| <= hmax along every great circle through u), at the direction u (body
   !> frame, need not be normalised, not a pole). The outward normal of the surface r(u) u there
   !> is along r u - g. One fused evaluation (`sh_sum_surface`), no allocation; the factors e_nm
   !> are computed at each call (about (N + 2)^2 / 2 square roots).
   pure subroutine radius_hessian(shape, u, r, g, hmax)
      !> Expansion (its Legendre table of degree nmax + 1).
      type(sh_expansion_type), intent(in) :: shape
      !> Direction, not along the z axis.
      real(wp), intent(in) :: u(3)
      !> r(u), gradient, largest |eigenvalue| of the Hessian.
      real(wp), intent(out) :: r, g(3), hmax
      real(wp) :: len, rho, ct, st, cp, sp, f(6), cot, h11, h12, h22, rn, rm
      real(wp) :: enm(size(shape%table%ca))
      integer :: m, n, k
      ! e_nm = sqrt((2n+1)(n^2-m^2)/(2n-1)), packed like the table (the theta-derivative factor of
      ! sh_sum_surface)
      do m = 0, shape%table%nmax
         k = shape%table%idx(m)
         rm = real(m, wp)
         enm(k) = 0.0_wp
         do n = m + 1, shape%table%nmax
            rn = real(n, wp)
            enm(k + n - m) = sqrt((2.0_wp * rn + 1.0_wp) * (rn * rn - rm * rm) / (2.0_wp * rn - 1.0_wp))
         end do
      end do
      len = sqrt(u(1)**2 + u(2)**2 + u(3)**2)
      rho = sqrt(u(1)**2 + u(2)**2)
      ct = u(3) / len
      st = rho / len
      cp = u(1) / rho
      sp = u(2) / rho
      ! r, r_t, r_p, r_tt, r_tp, r_pp (plain derivatives in theta and phi)
      call sh_sum_surface(shape%table, shape%a, shape%b, enm, shape%nmax, ct, st, cp, sp, f)
      r = f(1)
      g = f(2) * [ct * cp, ct * sp, -st] + (f(3) / st) * [-sp, cp, 0.0_wp]
      ! covariant Hessian in the frame (e_theta, e_phi)
      cot = ct / st
      h11 = f(4)
      h12 = (f(5) - cot * f(3)) / st
      h22 = f(6) / st**2 + cot * f(2)
      hmax = abs(0.5_wp * (h11 + h22)) + sqrt((0.5_wp * (h11 - h22))**2 + h12**2)
   end subroutine radius_hessian
end module anm_sh_hessian
