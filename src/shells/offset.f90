!> The outer radius R_t(u) of a shell of thickness t along one direction u.
!>
!> First the thesis' construction (Eq 2.1): find the surface point x(theta', phi') whose normal
!> offset x + t n lies on the ray, r(theta', phi') + t n(theta', phi') = (r(theta, phi) + beta) u,
!> by Newton-Raphson in (theta', phi') from the sample whose offset point is best aligned with u.
!> A Newton root is accepted only if it satisfies the distance definition of the shell: beta > 0,
!> u . n > 0, the offset point is a local minimum of the distance (positive definite Hessian of
!> |y - x|^2), and no other part of the surface is closer than t (checked with
!> `surface_distance`). Otherwise the direction falls back on the definition itself,
!> R_t(u) = max{rho : dist(rho u, particle) <= t}, found by safeguarded Newton/bisection on rho
!> (the set is an interval [0, R_t] because the dilated body is star-shaped about the centre).
!>
!> Usage:
!>     call offset_radius(surf, u, t, rt, used_fallback)
module anm_shells_offset
   use anm_core_kinds, only: wp, pi, two_pi
   use anm_shells_surface, only: shell_surface_type, eval_surface, surface_frame, surface_distance, cross3
   implicit none
   private

   public :: offset_radius, offset_newton

   !> Relative tolerance on distances (of t) when validating a Newton root.
   real(wp), parameter :: distance_tol = 1.0e-7_wp

contains

   !> Outer radius of the shell of thickness t along the unit direction u = (theta, phi).
   pure subroutine offset_radius(surf, theta, phi, t, rt, used_fallback)
      !> Surface data of the particle.
      type(shell_surface_type), intent(in) :: surf
      !> Direction (theta in (0, pi)).
      real(wp), intent(in) :: theta, phi
      !> Thickness (> 0).
      real(wp), intent(in) :: t
      !> R_t along the direction.
      real(wp), intent(out) :: rt
      !> True when the Newton construction had no valid root here.
      logical, intent(out) :: used_fallback
      real(wp) :: u(3), ts, ps, rho, dist, thc, phc, f(6), xs(3)
      logical :: ok

      u = [sin(theta) * cos(phi), sin(theta) * sin(phi), cos(theta)]
      call start_point(surf, u, t, ts, ps)
      call offset_newton(surf, theta, phi, t, ts, ps, rho, ok)
      if (ok) then
         call eval_surface(surf, ts, ps, f)
         xs = f(1) * [sin(ts) * cos(ps), sin(ts) * sin(ps), cos(ts)]
         call surface_distance(surf, rho * u, t, dist, thc, phc, known=xs)
         ok = dist >= t * (1.0_wp - distance_tol)
      end if
      used_fallback = .not. ok
      if (ok) then
         rt = rho
      else
         call definition_radius(surf, u, t, rt)
      end if
   end subroutine offset_radius

   !> The sample whose offset point x_s + t n_s is best aligned with u (the Newton start).
   pure subroutine start_point(surf, u, t, ts, ps)
      type(shell_surface_type), intent(in) :: surf
      real(wp), intent(in) :: u(3), t
      real(wp), intent(out) :: ts, ps
      real(wp) :: q(3), c, best, alpha, tu, pu, width, dphi
      integer :: i, j, jj, ib, jb, nt, np, j0, ncol
      logical :: all_phi

      nt = surf%grid%sphere%ntheta
      np = surf%grid%sphere%nphi
      dphi = two_pi / np
      ! the offset point of a surface point at angle > alpha from u cannot lie on the ray
      alpha = asin(min(1.0_wp, t / max(surf%rmin, tiny(t)))) + 2.0_wp * pi / nt
      tu = acos(max(-1.0_wp, min(1.0_wp, u(3))))
      pu = modulo(atan2(u(2), u(1)), two_pi)
      all_phi = tu - alpha <= 0.0_wp .or. tu + alpha >= pi
      if (.not. all_phi) then
         width = asin(min(1.0_wp, sin(alpha) / sin(tu))) + 2.0_wp * dphi
         all_phi = width >= pi .or. sin(alpha) >= sin(tu)
      end if
      if (all_phi) then
         j0 = 1
         ncol = np
      else
         j0 = floor((pu - width) / dphi) + 1
         ncol = floor((pu + width) / dphi) + 2 - j0
      end if
      best = -2.0_wp
      ib = 1
      jb = 1
      do jj = 1, ncol
         j = 1 + modulo(j0 + jj - 2, np)
         do i = 1, nt
            if (abs(surf%grid%sphere%theta(i) - tu) > alpha) cycle
            q = surf%x(:, i, j) + t * surf%n(:, i, j)
            c = dot_product(q, u) / norm2(q)
            if (c > best) then
               best = c
               ib = i
               jb = j
            end if
         end do
      end do
      ts = surf%grid%sphere%theta(ib)
      ps = surf%grid%sphere%phi(jb)
   end subroutine start_point

   !> Newton-Raphson for Eq 2.1 from (ts, ps): on success rho = r(theta, phi) + beta, the offset
   !> point is rho u, and the root passed the local checks (beta > 0, u . n > 0, local minimum).
   pure subroutine offset_newton(surf, theta, phi, t, ts, ps, rho, ok)
      !> Surface data.
      type(shell_surface_type), intent(in) :: surf
      !> Target direction.
      real(wp), intent(in) :: theta, phi
      !> Thickness.
      real(wp), intent(in) :: t
      !> Start (theta', phi'); the root on output.
      real(wp), intent(inout) :: ts, ps
      !> Distance of the offset point from the centre.
      real(wp), intent(out) :: rho
      !> Converged and locally valid.
      logical, intent(out) :: ok
      real(wp) :: u(3), e1(3), e2(3), f(6), x(3), xt(3), xp(3), xtt(3), xtp(3), xpp(3)
      real(wp) :: nv(3), nt(3), np(3), nn, nh(3), q(3), qt(3), qp(3), sgn
      real(wp) :: f1, f2, j11, j12, j21, j22, det, dt, dp, lam, res, scale
      real(wp) :: h11, h12, h22
      integer :: it

      u = [sin(theta) * cos(phi), sin(theta) * sin(phi), cos(theta)]
      e1 = [cos(theta) * cos(phi), cos(theta) * sin(phi), -sin(theta)]
      e2 = [-sin(phi), cos(phi), 0.0_wp]
      scale = surf%rmax + t
      ok = .false.
      rho = 0.0_wp
      do it = 1, 30
         if (abs(sin(ts)) < 1.0e-6_wp) return
         call eval_surface(surf, ts, ps, f)
         call surface_frame(ts, ps, f, x, xt, xp, xtt, xtp, xpp)
         sgn = sign(1.0_wp, sin(ts))
         nv = sgn * cross3(xt, xp)
         nn = norm2(nv)
         nh = nv / nn
         nt = sgn * (cross3(xtt, xp) + cross3(xt, xtp))
         np = sgn * (cross3(xtp, xp) + cross3(xt, xpp))
         nt = (nt - nh * dot_product(nh, nt)) / nn
         np = (np - nh * dot_product(nh, np)) / nn
         q = x + t * nh
         qt = xt + t * nt
         qp = xp + t * np
         f1 = dot_product(q, e1)
         f2 = dot_product(q, e2)
         res = sqrt(f1 * f1 + f2 * f2)
         if (res < 1.0e-13_wp * scale) then
            rho = dot_product(q, u)
            h11 = dot_product(xt, xt) - t * dot_product(nh, xtt)
            h12 = dot_product(xt, xp) - t * dot_product(nh, xtp)
            h22 = dot_product(xp, xp) - t * dot_product(nh, xpp)
            ok = rho > f(1) * dot_product(x / norm2(x), u) .and. dot_product(nh, u) > 0.0_wp &
                 .and. h11 > 0.0_wp .and. h11 * h22 - h12 * h12 > 0.0_wp .and. dot_product(q, u) > 0.0_wp
            if (ok) ok = rho > surf%shape%radius_dir(u)
            return
         end if
         j11 = dot_product(qt, e1)
         j12 = dot_product(qp, e1)
         j21 = dot_product(qt, e2)
         j22 = dot_product(qp, e2)
         det = j11 * j22 - j12 * j21
         if (abs(det) < tiny(det) * 1.0e10_wp) return
         dt = -(j22 * f1 - j12 * f2) / det
         dp = -(j11 * f2 - j21 * f1) / det
         lam = min(1.0_wp, 0.2_wp / max(abs(dt), abs(dp), tiny(dt)))
         ts = ts + lam * dt
         ps = ps + lam * dp
      end do
   end subroutine offset_newton

   !> R_t(u) = max{rho : dist(rho u, particle) <= t}: safeguarded Newton on
   !> g(rho) = dist(rho u) - t (g' = u . (y - x_c) / |y - x_c|) inside a shrinking bracket.
   pure subroutine definition_radius(surf, u, t, rt)
      type(shell_surface_type), intent(in) :: surf
      real(wp), intent(in) :: u(3), t
      real(wp), intent(out) :: rt
      real(wp) :: lo, hi, rho, d, thc, phc, f(6), xc(3), g1, rnew, tol
      integer :: it

      ! rho = r(u) + t is within t of the surface point r(u) u; beyond rmax + t nothing is
      lo = surf%shape%radius_dir(u) + t
      hi = 1.05_wp * surf%rmax + t + surf%hmax
      tol = 1.0e-12_wp * hi
      rho = 0.5_wp * (lo + hi)
      do it = 1, 200
         call surface_distance(surf, rho * u, t, d, thc, phc)
         if (d <= t) then
            lo = rho
         else
            hi = rho
         end if
         if (hi - lo <= tol) exit
         rnew = -1.0_wp
         if (d < huge(d)) then
            call eval_surface(surf, thc, phc, f)
            xc = f(1) * [sin(thc) * cos(phc), sin(thc) * sin(phc), cos(thc)]
            g1 = dot_product(u, rho * u - xc) / max(d, tiny(d))
            if (abs(d - t) <= 1.0e-12_wp * t .and. g1 > 0.0_wp) then
               rt = rho
               return
            end if
            if (g1 > 1.0e-3_wp) rnew = rho - (d - t) / g1
         end if
         if (rnew <= lo .or. rnew >= hi) rnew = 0.5_wp * (lo + hi)
         rho = rnew
      end do
      rt = 0.5_wp * (lo + hi)
   end subroutine definition_radius
end module anm_shells_offset
