!> The one evaluation kernel of real spherical-harmonic sums at a direction: every fused
!> evaluation of r(theta, phi) in Anm (expansions, shell surfaces, slice stacks) runs here.
!>
!> The sum is r = sum_{m=0..N} sum_{n=m..N} Pbar_n^m(x) (A_nm cos(m phi) + B_nm sin(m phi)),
!> x = cos(theta), s = sin(theta) (docs/conventions.md). For each order m the sectoral value is
!> advanced by Pbar_m^m = -sqrt((2m+1)/(2m)) s Pbar_{m-1}^{m-1} from Pbar_0^0 = 1/sqrt(4 pi)
!> (`order_step`, which also rotates cos(m phi), sin(m phi) by the Chebyshev recurrence: no
!> trigonometric call per term), and the column n = m+1..N follows from the three-term recurrence
!> Pbar_n^m = ca x Pbar_{n-1}^m - cb Pbar_{n-2}^m of the `legendre_table_type` (`column_first`,
!> `column_next`). Orders whose sectoral value has fallen below `sectoral_cutoff` are skipped:
!> their contribution is below 1e-150 of r for any degree <= 100. These three steps and the two
!> constants are written once, here.
!>
!> What is summed differs per caller, and the sums are fused with the recurrence (no column is
!> stored: the recurrence is latency-bound and the sums hide in it), so the kernel has one variant
!> per set of sums; each variant is the same loop over (m, n):
!> - `sh_sum`: r (the contact-test hot path, `sh_expansion_type%radius_dir`);
!> - `sh_sum_slope`: r and the two angular derivatives sin(theta) r_theta and r_phi
!>   (`radius_slope`);
!> - `sh_sum_surface`: r and its first and second derivatives (`eval_surface` of the shells);
!> - `sh_sum_surface_lanes`: the same at `sh_lanes` points at once (one vector register per
!>   quantity; no cut-off, since the lanes share one loop);
!> - `sh_sum_forms`: r of several expansions stored side by side (the slice stacks).
!> The variants are kept apart, not parametrised by run-time flags, because a flag tested inside
!> the inner loop costs up to a third of the time of these short loops. Their length is that of
!> one fused loop each.
!>
!> Usage:
!>     r = sh_sum(table, a, b, nmax, cos(theta), sin(theta), cos(phi), sin(phi))
module anm_sh_kernel
   use anm_core_kinds, only: wp, inv_sqrt_4pi
   use anm_sh_legendre, only: legendre_table_type
   implicit none
   private

   public :: sh_lanes, sectoral_cutoff, sh_sum, sh_sum_slope, sh_sum_surface, sh_sum_surface_lanes, &
      & sh_sum_forms

   !> Points per call of `sh_sum_surface_lanes` (four AVX-512 registers per quantity: independent
   !> recurrence chains, all in L1; 8 and 16 were slower, 64 no better).
   integer, parameter :: sh_lanes = 32
   !> Orders whose sectoral value Pbar_m^m falls below this are skipped (with every higher order).
   real(wp), parameter :: sectoral_cutoff = 1.0e-250_wp

contains

   !> Advance from order m-1 to order m: the sectoral value pmm and cos(m phi), sin(m phi).
   elemental subroutine order_step(sect, s, cp, sp, pmm, cm, sm)
      !> sqrt((2m+1)/(2m)) (`legendre_table_type%sect(m)`).
      real(wp), intent(in) :: sect
      !> sin(theta), cos(phi), sin(phi).
      real(wp), intent(in) :: s, cp, sp
      !> Pbar_{m-1}^{m-1} on input, Pbar_m^m on output.
      real(wp), intent(inout) :: pmm
      !> cos and sin of (m-1) phi on input, of m phi on output.
      real(wp), intent(inout) :: cm, sm
      real(wp) :: cnew
      pmm = -sect * s * pmm
      cnew = cm * cp - sm * sp
      sm = sm * cp + cm * sp
      cm = cnew
   end subroutine order_step

   !> First step of the column recurrence: Pbar_{m+1}^m = ca x Pbar_m^m.
   elemental function column_first(ca, x, v) result(p)
      !> Recurrence factor, cos(theta), Pbar_m^m.
      real(wp), intent(in) :: ca, x, v
      real(wp) :: p
      p = ca * x * v
   end function column_first

   !> Column recurrence: Pbar_n^m = ca x Pbar_{n-1}^m - cb Pbar_{n-2}^m.
   elemental function column_next(ca, cb, x, v1, v0) result(p)
      !> Recurrence factors, cos(theta), Pbar_{n-1}^m, Pbar_{n-2}^m.
      real(wp), intent(in) :: ca, cb, x, v1, v0
      real(wp) :: p
      p = ca * x * v1 - cb * v0
   end function column_next

   !> r = sum Pbar_n^m(x) (A_nm cos m phi + B_nm sin m phi) at one direction.
   pure function sh_sum(table, a, b, nmax, x, s, cp, sp) result(r)
      !> Recursion table of degree >= nmax + 1.
      type(legendre_table_type), intent(in) :: table
      !> Cosine and sine coefficients (n, m).
      real(wp), intent(in), contiguous :: a(0:, 0:), b(0:, 0:)
      !> Degree.
      integer, intent(in) :: nmax
      !> cos(theta), sin(theta), cos(phi), sin(phi).
      real(wp), intent(in) :: x, s, cp, sp
      real(wp) :: r
      real(wp) :: pmm, v0, v1, v2, cm, sm, acc_a, acc_b
      integer :: m, n, k0

      pmm = inv_sqrt_4pi
      cm = 1.0_wp   ! cos(m phi)
      sm = 0.0_wp   ! sin(m phi)
      r = 0.0_wp
      do m = 0, nmax
         if (m > 0) then
            call order_step(table%sect(m), s, cp, sp, pmm, cm, sm)
            if (abs(pmm) < sectoral_cutoff) exit
         end if
         k0 = table%idx(m)
         v1 = pmm
         acc_a = a(m, m) * v1
         acc_b = b(m, m) * v1
         if (m < nmax) then
            v0 = v1
            v1 = column_first(table%ca(k0 + 1), x, v0)
            acc_a = acc_a + a(m + 1, m) * v1
            acc_b = acc_b + b(m + 1, m) * v1
            do n = m + 2, nmax
               v2 = column_next(table%ca(k0 + n - m), table%cb(k0 + n - m), x, v1, v0)
               v0 = v1
               v1 = v2
               acc_a = acc_a + a(n, m) * v1
               acc_b = acc_b + b(n, m) * v1
            end do
         end if
         r = r + acc_a * cm + acc_b * sm
      end do
   end function sh_sum

   !> r, sin(theta) dr/dtheta and dr/dphi at one direction off the poles (s > 0). The theta
   !> derivative uses sin(theta) dPbar_n^m/dtheta = n x Pbar_n^m - f_nm Pbar_{n-1}^m with
   !> f_nm = (2n+1)/ca (`legendre_table_type%dq`).
   pure subroutine sh_sum_slope(table, a, b, nmax, x, s, cp, sp, r, rt, rp)
      !> Recursion table of degree >= nmax + 1.
      type(legendre_table_type), intent(in) :: table
      !> Cosine and sine coefficients (n, m).
      real(wp), intent(in), contiguous :: a(0:, 0:), b(0:, 0:)
      !> Degree.
      integer, intent(in) :: nmax
      !> cos(theta), sin(theta), cos(phi), sin(phi).
      real(wp), intent(in) :: x, s, cp, sp
      !> r, sin(theta) dr/dtheta, dr/dphi.
      real(wp), intent(out) :: r, rt, rp
      real(wp) :: pmm, v0, v1, v2, cm, sm, acc_a, acc_b, dt_a, dt_b
      integer :: m, n, k0

      pmm = inv_sqrt_4pi
      cm = 1.0_wp
      sm = 0.0_wp
      r = 0.0_wp
      rt = 0.0_wp
      rp = 0.0_wp
      do m = 0, nmax
         if (m > 0) then
            call order_step(table%sect(m), s, cp, sp, pmm, cm, sm)
            if (abs(pmm) < sectoral_cutoff) exit
         end if
         k0 = table%idx(m)
         v1 = pmm
         acc_a = a(m, m) * v1
         acc_b = b(m, m) * v1
         ! sin(theta) dPbar_m^m/dtheta = m x Pbar_m^m
         dt_a = a(m, m) * (m * x * v1)
         dt_b = b(m, m) * (m * x * v1)
         v0 = 0.0_wp
         do n = m + 1, nmax
            if (n == m + 1) then
               v2 = column_first(table%ca(k0 + 1), x, v1)
            else
               v2 = column_next(table%ca(k0 + n - m), table%cb(k0 + n - m), x, v1, v0)
            end if
            v0 = v1
            v1 = v2
            acc_a = acc_a + a(n, m) * v1
            acc_b = acc_b + b(n, m) * v1
            v2 = n * x * v1 - table%dq(k0 + n - m) * v0
            dt_a = dt_a + a(n, m) * v2
            dt_b = dt_b + b(n, m) * v2
         end do
         r = r + acc_a * cm + acc_b * sm
         rt = rt + dt_a * cm + dt_b * sm
         rp = rp + m * (acc_b * cm - acc_a * sm)
      end do
   end subroutine sh_sum_slope

   !> r and its derivatives at one direction: f = [r, r_t, r_p, r_tt, r_tp, r_pp] (t = theta,
   !> p = phi, plain derivatives). s may be negative (theta outside [0, pi]) but not tiny.
   pure subroutine sh_sum_surface(table, a, b, enm, nmax, x, s, cp, sp, f)
      !> Recursion table of degree >= nmax + 1.
      type(legendre_table_type), intent(in) :: table
      !> Cosine and sine coefficients (n, m).
      real(wp), intent(in), contiguous :: a(0:, 0:), b(0:, 0:)
      !> e_nm = sqrt((2n+1)(n^2-m^2)/(2n-1)), packed like the table.
      real(wp), intent(in), contiguous :: enm(:)
      !> Degree.
      integer, intent(in) :: nmax
      !> cos(theta), sin(theta), cos(phi), sin(phi).
      real(wp), intent(in) :: x, s, cp, sp
      !> r, dr/dt, dr/dp, d2r/dt2, d2r/dtdp, d2r/dp2.
      real(wp), intent(out) :: f(6)
      real(wp) :: cm, sm, pmm, p0, p1, p2, d1, cots, inv_s, msq
      real(wp) :: a0, b0, a1, b1, ann, bnn, rn
      integer :: m, n, k0

      inv_s = 1.0_wp / s
      cots = x * inv_s
      pmm = inv_sqrt_4pi
      cm = 1.0_wp
      sm = 0.0_wp
      f = 0.0_wp
      do m = 0, nmax
         if (m > 0) then
            call order_step(table%sect(m), s, cp, sp, pmm, cm, sm)
            if (abs(pmm) < sectoral_cutoff) exit
         end if
         k0 = table%idx(m)
         ! n = m
         p0 = 0.0_wp
         p1 = pmm
         d1 = m * x * p1 * inv_s
         rn = real(m, wp)
         a0 = a(m, m) * p1
         b0 = b(m, m) * p1
         a1 = a(m, m) * d1
         b1 = b(m, m) * d1
         ann = a(m, m) * rn * (rn + 1.0_wp) * p1
         bnn = b(m, m) * rn * (rn + 1.0_wp) * p1
         do n = m + 1, nmax
            rn = real(n, wp)
            if (n == m + 1) then
               p2 = column_first(table%ca(k0 + 1), x, p1)
            else
               p2 = column_next(table%ca(k0 + n - m), table%cb(k0 + n - m), x, p1, p0)
            end if
            p0 = p1
            p1 = p2
            d1 = (rn * x * p1 - enm(k0 + n - m) * p0) * inv_s
            a0 = a0 + a(n, m) * p1
            b0 = b0 + b(n, m) * p1
            a1 = a1 + a(n, m) * d1
            b1 = b1 + b(n, m) * d1
            ann = ann + a(n, m) * rn * (rn + 1.0_wp) * p1
            bnn = bnn + b(n, m) * rn * (rn + 1.0_wp) * p1
         end do
         msq = real(m * m, wp)
         f(1) = f(1) + a0 * cm + b0 * sm
         f(2) = f(2) + a1 * cm + b1 * sm
         f(3) = f(3) + m * (b0 * cm - a0 * sm)
         ! Legendre equation: P'' = -cot(theta) P' - (n(n+1) - m^2/sin^2) P
         f(4) = f(4) + (-cots * a1 - ann + msq * inv_s * inv_s * a0) * cm + (-cots * b1 - bnn + msq * inv_s * inv_s * b0) * sm
         f(5) = f(5) + m * (b1 * cm - a1 * sm)
         f(6) = f(6) - msq * (a0 * cm + b0 * sm)
      end do
   end subroutine sh_sum_surface

   !> `sh_sum_surface` at `sh_lanes` directions at once; the azimuthal factors are summed once per
   !> order and r_thetatheta follows from the Legendre equation at the end. No cut-off (the lanes
   !> share the loop; values below the double range flush to zero).
   pure subroutine sh_sum_surface_lanes(table, a, b, enm, nmax, x, s, cp, sp, f)
      !> Recursion table of degree >= nmax + 1.
      type(legendre_table_type), intent(in) :: table
      !> Cosine and sine coefficients (n, m).
      real(wp), intent(in), contiguous :: a(0:, 0:), b(0:, 0:)
      !> e_nm = sqrt((2n+1)(n^2-m^2)/(2n-1)), packed like the table.
      real(wp), intent(in), contiguous :: enm(:)
      !> Degree.
      integer, intent(in) :: nmax
      !> cos(theta), sin(theta) (not tiny), cos(phi), sin(phi) per lane.
      real(wp), intent(in) :: x(sh_lanes), s(sh_lanes), cp(sh_lanes), sp(sh_lanes)
      !> f(k, :) = r, dr/dt, dr/dp, d2r/dt2, d2r/dtdp, d2r/dp2 at lane k.
      real(wp), intent(out) :: f(sh_lanes, 6)
      real(wp), dimension(sh_lanes) :: cm, sm, pmm, p0, p1, p2, d1, cots, inv_s, &
                                       a0, b0, a1, b1, ann, bnn, f1, f2, f3, f4, f5, f6, t0
      real(wp) :: an, bn, ca, cb, en, rn, nn1, msq, rm
      integer :: m, n, k0

      inv_s = 1.0_wp / s
      cots = x * inv_s
      pmm = inv_sqrt_4pi
      cm = 1.0_wp
      sm = 0.0_wp
      f1 = 0.0_wp
      f2 = 0.0_wp
      f3 = 0.0_wp
      f4 = 0.0_wp
      f5 = 0.0_wp
      f6 = 0.0_wp
      do m = 0, nmax
         if (m > 0) call order_step(table%sect(m), s, cp, sp, pmm, cm, sm)
         k0 = table%idx(m)
         rn = real(m, wp)
         nn1 = rn * (rn + 1.0_wp)
         an = a(m, m)
         bn = b(m, m)
         p0 = 0.0_wp
         p1 = pmm
         d1 = rn * x * p1 * inv_s
         a0 = an * p1
         b0 = bn * p1
         a1 = an * d1
         b1 = bn * d1
         ann = an * nn1 * p1
         bnn = bn * nn1 * p1
         do n = m + 1, nmax
            rn = real(n, wp)
            nn1 = rn * (rn + 1.0_wp)
            ca = table%ca(k0 + n - m)
            cb = merge(0.0_wp, table%cb(k0 + n - m), n == m + 1)
            en = enm(k0 + n - m)
            an = a(n, m)
            bn = b(n, m)
            p2 = column_next(ca, cb, x, p1, p0)
            p0 = p1
            p1 = p2
            d1 = (rn * x * p1 - en * p0) * inv_s
            a0 = a0 + an * p1
            b0 = b0 + bn * p1
            a1 = a1 + an * d1
            b1 = b1 + bn * d1
            ann = ann + (an * nn1) * p1
            bnn = bnn + (bn * nn1) * p1
         end do
         rm = real(m, wp)
         msq = rm * rm
         ! the azimuthal factors (r_thetatheta from the Legendre equation at the end)
         t0 = a0 * cm + b0 * sm
         f1 = f1 + t0
         f6 = f6 - msq * t0
         f2 = f2 + (a1 * cm + b1 * sm)
         f3 = f3 + rm * (b0 * cm - a0 * sm)
         f5 = f5 + rm * (b1 * cm - a1 * sm)
         f4 = f4 + (ann * cm + bnn * sm)
      end do
      ! Legendre equation: r_thetatheta = -cot r_theta - sum n (n + 1) r_nm - r_phiphi / sin^2
      f(:, 1) = f1
      f(:, 2) = f2
      f(:, 3) = f3
      f(:, 4) = -cots * f2 - f4 - f6 * (inv_s * inv_s)
      f(:, 5) = f5
      f(:, 6) = f6
   end subroutine sh_sum_surface_lanes

   !> r of np expansions stored side by side at one direction: c(k, n, m) holds the cosine
   !> coefficients of expansion k and c(np + k, n, m) its sine coefficients.
   pure subroutine sh_sum_forms(table, c, np, nmax, x, s, cp, sp, r)
      !> Recursion table of degree >= nmax + 1.
      type(legendre_table_type), intent(in) :: table
      !> Coefficients (2 np, 0:nmax, 0:nmax).
      real(wp), intent(in), contiguous :: c(:, 0:, 0:)
      !> Number of expansions (a multiple of the vector width is fastest).
      integer, intent(in) :: np
      !> Degree.
      integer, intent(in) :: nmax
      !> cos(theta), sin(theta), cos(phi), sin(phi).
      real(wp), intent(in) :: x, s, cp, sp
      !> r(k) of expansion k.
      real(wp), intent(out) :: r(np)
      real(wp) :: acc(2 * np)
      real(wp) :: pmm, v0, v1, v2, cm, sm
      integer :: m, n, k0

      pmm = inv_sqrt_4pi
      cm = 1.0_wp
      sm = 0.0_wp
      r = 0.0_wp
      do m = 0, nmax
         if (m > 0) then
            call order_step(table%sect(m), s, cp, sp, pmm, cm, sm)
            if (abs(pmm) < sectoral_cutoff) exit
         end if
         k0 = table%idx(m)
         v1 = pmm
         acc = c(:, m, m) * v1
         if (m < nmax) then
            v0 = v1
            v1 = column_first(table%ca(k0 + 1), x, v0)
            acc = acc + c(:, m + 1, m) * v1
            do n = m + 2, nmax
               v2 = column_next(table%ca(k0 + n - m), table%cb(k0 + n - m), x, v1, v0)
               v0 = v1
               v1 = v2
               acc = acc + c(:, n, m) * v1
            end do
         end if
         r = r + acc(1:np) * cm + acc(np + 1:2 * np) * sm
      end do
   end subroutine sh_sum_forms
end module anm_sh_kernel
