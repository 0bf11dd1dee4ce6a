!> Per-shape contact data: the truncated expansion, certified bounds of r over a hierarchy of
!> angular patches, guaranteed bounding radii and extent boxes.
!>
!> Patches are latitude-longitude rectangles. Level l has nt = 4 2^l rows in theta and
!> np = 8 2^l columns in phi (square patches of pi/nt rad). Levels 0..`leaf_level` store per
!> patch a cap (centre direction, half-angle alpha) that contains it, certified
!> r_min <= r <= r_max over the patch, and a ball that contains the solid shell sector
!> {rho u : u in cap, r_min <= rho <= r_max}. Levels leaf_level+1..`stored_level` store only the
!> certified bounds (single precision, rounded outwards); their caps come from per-row and
!> per-column tables (`patch_geometry`). Finer levels are generated on the fly by the contact test
!> (same indexing) with the local bound of `slope_bound`.
!>
!> Certification (docs/contact.md). r is sampled with its gradient on the regular grid
!> theta_i = i pi/nt_g, phi_j = 2 pi j/np_g (nt_g = 8 nt_leaf, np_g = 8 np_leaf). The restriction
!> of a degree-N expansion to any great circle is a trigonometric polynomial of degree <= N, so by
!> Bernstein's inequality, with M = max |r - c| over the sphere for any constant c,
!>     |dr/ds| <= N M (Lipschitz bound G) and |d2r/ds2| <= N^2 M (curvature bound H)
!> along every great circle (s = arc length). Every point of a grid cell is within
!> d_c = (dtheta + sin_max dphi)/2 of one of its corners, so over the cell
!>     r <= max_k (r_k + |grad r_k| d_c) + H d_c^2 / 2,   r >= min_k (r_k - |grad r_k| d_c) - H d_c^2 / 2.
!> M itself is certified from the samples: with M_s = max |r_k - c| and d = max d_c,
!> M <= M_s + G d = M_s + N M d, so M <= M_s / (1 - N d) (requires N d < 1).
!>
!> Usage:
!>     call new_contact_body(body, shape, error, nused=14)
!>     ! body%r_max, body%box_lo/box_hi (certified), body%ext_lo/ext_hi (thesis N_ext scan)
module anm_contact_body
   use anm_core_kinds, only: wp, sp, pi, two_pi
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string
   use anm_sh_expansion, only: sh_expansion_type, sh_truncate
   use anm_sh_legendre, only: legendre_values, legendre_theta_derivatives, packed_size
   use anm_geometry_extent, only: extent_scan
   implicit none
   private

   public :: contact_body_type, new_contact_body, leaf_level, stored_level, patch_rows, patch_cols, patch_index, &
      & patch_cap, sector_ball, default_next, patch_geometry, patch_bounds, slope_bound
   public :: node_size, nd_dir, nd_cosa, nd_sina, nd_c, nd_r, nd_e, nd_h, nd_ball, nd_brad, nd_rc

   !> Finest stored patch level (64 x 128 patches of pi/64 rad).
   integer, parameter :: leaf_level = 4
   !> Finest level with stored bounds (256 x 512 patches of pi/256 rad, 2 x 2 certification cells).
   integer, parameter :: stored_level = 6
   !> Grid cells per leaf patch edge used to certify the bounds.
   integer, parameter :: cells_per_leaf = 8
   !> Thesis default N_ext.
   integer, parameter :: default_next = 40

   !> Layout of a column of `contact_body_type%node` (one patch of levels 0..leaf_level): cap
   !> centre direction (3), cos and sin of the cap half-angle; oriented box of the surface piece:
   !> centre (3), radius of a ball about the centre containing the box, axes (3 x 3, columns; the
   !> third is the surface normal at the patch centre), half-extents (3); sector ball centre (3)
   !> and radius; r at the cap centre direction.
   integer, parameter :: nd_dir = 1, nd_cosa = 4, nd_sina = 5, nd_c = 6, nd_r = 9, nd_e = 10, nd_h = 19, &
                         nd_ball = 22, nd_brad = 25, nd_rc = 26, node_size = 26

   !> Immutable per-(shape, order) contact data, shared by all particles of that shape and by all
   !> threads.
   type :: contact_body_type
      !> Expansion truncated to the order used.
      type(sh_expansion_type) :: shape
      !> Order used.
      integer :: nmax = -1
      !> Certified upper bound of r over the sphere (shape units).
      real(wp) :: r_max = 0.0_wp
      !> Certified lower bound of r over the sphere (shape units).
      real(wp) :: r_min = 0.0_wp
      !> Certified Lipschitz bound of r along great circles, N M (shape units per radian).
      real(wp) :: lipschitz = 0.0_wp
      !> Certified bound of |d2r/ds2| along great circles, N^2 M.
      real(wp) :: curvature = 0.0_wp
      !> Certified bound of |d3r/ds3| along great circles, N^3 M.
      real(wp) :: third = 0.0_wp
      !> Guaranteed extent box (body frame): every surface point lies inside [box_lo, box_hi].
      real(wp) :: box_lo(3) = 0.0_wp, box_hi(3) = 0.0_wp
      !> Thesis extent box from the N_ext angular scan (slightly inside the true box).
      real(wp) :: ext_lo(3) = 0.0_wp, ext_hi(3) = 0.0_wp
      !> N_ext used for ext_lo/ext_hi.
      integer :: next = default_next
      !> Offset of level l in the patch arrays (patch k of level l is off(l) + k).
      integer :: off(0:leaf_level + 1) = 0
      !> Cap centre direction of each patch (3, npatch).
      real(wp), allocatable :: dir(:, :)
      !> cos and sin of the cap half-angle.
      real(wp), allocatable :: cosa(:), sina(:)
      !> Certified bounds of r over the patch.
      real(wp), allocatable :: rlo(:), rhi(:)
      !> Ball containing the shell sector: centre (3, npatch) and radius.
      real(wp), allocatable :: ball(:, :), brad(:)
      !> Offset of level l (leaf_level < l <= stored_level) in dlo/dhi.
      integer :: doff(leaf_level + 1:stored_level + 1) = 0
      !> Certified bounds of r over the patches of levels leaf_level+1..stored_level, rounded
      !> outwards to single precision (patch (l, i, j) at doff(l) + (j - 1) patch_rows(l) + i).
      real(sp), allocatable :: dlo(:), dhi(:)
      !> Offsets of level l (0..stored_level) in the row and column tables.
      integer :: roff(0:stored_level) = 0, coff(0:stored_level) = 0
      !> Per patch row: cos and sin of the mid polar angle, cos and sin of the cap half-angle.
      real(wp), allocatable :: row_ct(:), row_st(:), row_cosa(:), row_sina(:)
      !> Per patch column: cos and sin of the mid azimuth.
      real(wp), allocatable :: col_cp(:), col_sp(:)
      !> Per patch of levels 0..leaf_level (same indexing as `dir`), packed for the contact
      !> traversal (layout nd_*, node_size rows): the cap and sector ball (copies of dir, cosa,
      !> sina, ball, brad), r at the cap centre direction (a surface point) and the oriented box
      !> of the surface piece {r(u) u : u in patch}: every such point x has |e_i . (x - c)| <= h_i
      !> (certified, `surface_boxes`).
      real(wp), allocatable :: node(:, :)
   end type contact_body_type

contains

   !> Patch rows (theta) at level l.
   elemental function patch_rows(l) result(n)
      !> Level.
      integer, intent(in) :: l
      integer :: n
      n = 4 * 2**l
   end function patch_rows

   !> Patch columns (phi) at level l.
   elemental function patch_cols(l) result(n)
      !> Level.
      integer, intent(in) :: l
      integer :: n
      n = 8 * 2**l
   end function patch_cols

   !> Storage index of patch (i, j) of a stored level l.
   pure function patch_index(body, l, i, j) result(k)
      !> Body.
      type(contact_body_type), intent(in) :: body
      !> Level, theta row 1..patch_rows(l), phi column 1..patch_cols(l).
      integer, intent(in) :: l, i, j
      integer :: k
      k = body%off(l) + (j - 1) * patch_rows(l) + i
   end function patch_index

   !> Cap of patch (l, i, j), l <= stored_level, from the row and column tables (no trigonometry).
   pure subroutine patch_geometry(body, l, i, j, dir, cosa, sina)
      !> Body.
      type(contact_body_type), intent(in) :: body
      !> Level (<= stored_level), row, column.
      integer, intent(in) :: l, i, j
      !> Cap centre direction.
      real(wp), intent(out) :: dir(3)
      !> cos and sin of the cap half-angle.
      real(wp), intent(out) :: cosa, sina
      integer :: kr, kc
      kr = body%roff(l) + i
      kc = body%coff(l) + j
      dir = [body%row_st(kr) * body%col_cp(kc), body%row_st(kr) * body%col_sp(kc), body%row_ct(kr)]
      cosa = body%row_cosa(kr)
      sina = body%row_sina(kr)
   end subroutine patch_geometry

   !> Certified bounds of r over patch (l, i, j), l <= stored_level.
   pure subroutine patch_bounds(body, l, i, j, rlo, rhi)
      !> Body.
      type(contact_body_type), intent(in) :: body
      !> Level (<= stored_level), row, column.
      integer, intent(in) :: l, i, j
      !> Lower and upper bound of r over the patch.
      real(wp), intent(out) :: rlo, rhi
      integer :: k
      if (l <= leaf_level) then
         k = body%off(l) + (j - 1) * patch_rows(l) + i
         rlo = body%rlo(k)
         rhi = body%rhi(k)
      else
         k = body%doff(l) + (j - 1) * patch_rows(l) + i
         rlo = real(body%dlo(k), wp)
         rhi = real(body%dhi(k), wp)
      end if
   end subroutine patch_bounds

   !> Local bound of r over the cap of half-angle alpha around a direction u0 where r = r0 and
   !> |grad r| = g0 (from `radius_slope`): |r(u) - r0| <= g0 alpha + H alpha^2/2, by Taylor's
   !> theorem along the great-circle arc from u0 to u (length <= alpha) with the certified curvature
   !> bound H = N^2 M. `sin0` = sin(theta(u0)) sets the rounding margin of g0.
   pure function slope_bound(body, g0, alpha, sin0) result(w)
      !> Body.
      type(contact_body_type), intent(in) :: body
      !> |grad r| at the cap centre, cap half-angle (rad), sin of the centre's polar angle.
      real(wp), intent(in) :: g0, alpha, sin0
      real(wp) :: w
      real(wp) :: gm
      gm = g0 * (1.0_wp + 1.0e-12_wp) + 1.0e-14_wp * (body%nmax + 1)**2 * body%r_max / max(sin0, 1.0e-300_wp)
      w = (gm * alpha + 0.5_wp * body%curvature * alpha**2) * (1.0_wp + 1.0e-12_wp) + 1.0e-14_wp * body%r_max
   end function slope_bound

   !> Cap containing the rectangle [th0, th1] x [ph0, ph1] (ph1 - ph0 <= pi/2): centre direction
   !> at the mid angles, half-angle the largest angle to a corner (along edges of such rectangles
   !> the angle to the centre is largest at the corners), plus a rounding margin.
   pure subroutine patch_cap(th0, th1, ph0, ph1, dir, cosa, sina)
      !> Polar range and azimuth range (radians).
      real(wp), intent(in) :: th0, th1, ph0, ph1
      !> Centre direction.
      real(wp), intent(out) :: dir(3)
      !> cos and sin of the half-angle.
      real(wp), intent(out) :: cosa, sina
      real(wp) :: tm, pm, c, cmin
      tm = 0.5_wp * (th0 + th1)
      pm = 0.5_wp * (ph0 + ph1)
      dir = [sin(tm) * cos(pm), sin(tm) * sin(pm), cos(tm)]
      cmin = 1.0_wp
      c = cos(tm) * cos(th0) + sin(tm) * sin(th0) * cos(0.5_wp * (ph1 - ph0))
      cmin = min(cmin, c)
      c = cos(tm) * cos(th1) + sin(tm) * sin(th1) * cos(0.5_wp * (ph1 - ph0))
      cmin = min(cmin, c)
      ! rounding margin of 1e-12 rad on the half-angle
      cosa = max(-1.0_wp, min(1.0_wp, cmin))
      sina = sqrt(max(0.0_wp, 1.0_wp - cosa**2))
      c = cosa * cos(1.0e-12_wp) - sina * sin(1.0e-12_wp)
      sina = sina * cos(1.0e-12_wp) + cosa * sin(1.0e-12_wp)
      cosa = c
   end subroutine patch_cap

   !> Ball containing {rho u : angle(u, dir) <= alpha, rlo <= rho <= rhi}: centre on the axis at
   !> (rlo cos alpha + rhi)/2; the farthest points are on the rim circles.
   pure subroutine sector_ball(dir, cosa, sina, rlo, rhi, center, radius)
      !> Cap direction.
      real(wp), intent(in) :: dir(3)
      !> cos, sin of the cap half-angle.
      real(wp), intent(in) :: cosa, sina
      !> Radial range (rlo >= 0).
      real(wp), intent(in) :: rlo, rhi
      !> Ball centre.
      real(wp), intent(out) :: center(3)
      !> Ball radius.
      real(wp), intent(out) :: radius
      real(wp) :: rm, lo
      lo = max(0.0_wp, rlo)
      rm = 0.5_wp * (lo * max(cosa, 0.0_wp) + rhi)
      center = rm * dir
      radius = max(sqrt(max(0.0_wp, rhi**2 + rm**2 - 2.0_wp * rhi * rm * cosa)), &
                   sqrt(max(0.0_wp, lo**2 + rm**2 - 2.0_wp * lo * rm * cosa)), abs(rm - lo), rhi - rm)
      radius = radius * (1.0_wp + 4.0_wp * epsilon(1.0_wp)) + 4.0_wp * epsilon(1.0_wp) * rhi
   end subroutine sector_ball

   !> Build the contact data of `shape` truncated to order `nused` (default: all of it).
   subroutine new_contact_body(body, shape, error, nused, next)
      !> Contact data to build.
      type(contact_body_type), intent(out) :: body
      !> Star-shaped surface r(theta, phi) (a particle, or a particle-plus-shell outer surface).
      type(sh_expansion_type), intent(in) :: shape
      !> Error when the shape is not star-shaped (certified r_min <= 0) or too rough for the grid.
      type(error_type), allocatable, intent(out) :: error
      !> Order used (default: shape%nmax).
      integer, intent(in), optional :: nused
      !> N_ext of the thesis extent box stored in ext_lo/ext_hi (default 40).
      integer, intent(in), optional :: next
      real(wp), allocatable :: rg(:, :), gg(:, :), rt(:, :), rp(:, :), clo(:, :), chi(:, :), dcr(:), h11(:, :), &
                               h12(:, :), h22(:, :), qhi(:, :), qlo(:, :)
      integer :: ntg, npg, nleaf_t, nleaf_p, i, j, l, k, n, ic, jc, np_tot, kc, nd
      real(wp) :: dth, dph, smin, smax, ms, dmax, mm, dc, smx, hi, lo, ang, mu, d3(3), margin
      real(wp) :: e(3)

      if (present(nused)) then
         body%shape = sh_truncate(shape, nused)
      else
         body%shape = sh_truncate(shape, shape%nmax)
      end if
      n = body%shape%nmax
      body%nmax = n
      if (present(next)) body%next = max(2, next)
      nleaf_t = patch_rows(leaf_level)
      nleaf_p = patch_cols(leaf_level)
      ntg = cells_per_leaf * nleaf_t
      npg = cells_per_leaf * nleaf_p
      dth = pi / ntg
      dph = two_pi / npg
      allocate (rg(0:ntg, 0:npg), gg(0:ntg, 0:npg), rt(0:ntg, 0:npg), rp(0:ntg, 0:npg), h11(0:ntg, 0:npg), &
                h12(0:ntg, 0:npg), h22(0:ntg, 0:npg))
      call synthesize_regular(body%shape, ntg, npg, rg, rt, rp, h11, h12, h22)
      gg = sqrt(rt**2 + rp**2)
      ! largest and smallest eigenvalue of the Hessian, clipped at 0
      qhi = max(0.0_wp, 0.5_wp * (h11 + h22) + sqrt((0.5_wp * (h11 - h22))**2 + h12**2))
      qlo = min(0.0_wp, 0.5_wp * (h11 + h22) - sqrt((0.5_wp * (h11 - h22))**2 + h12**2))
      smin = minval(rg)
      smax = maxval(rg)
      ms = 0.5_wp * (smax - smin)
      dmax = 0.5_wp * (dth + dph)
      if (n * dmax >= 0.5_wp) then
         call fatal_error(error, "contact body: order "//to_string(n)//" too high for the certification grid", &
                          error_code%value)
         return
      end if
      mm = ms / (1.0_wp - n * dmax) * (1.0_wp + 1.0e-12_wp) + 1.0e-14_wp * smax
      if (n == 0) mm = 0.0_wp
      body%lipschitz = n * mm
      body%curvature = real(n, wp)**2 * mm
      ! cell bounds: first order with the Bernstein curvature H; for cells not touching a pole
      ! also second order, r <= max_k (r_k + |grad r_k| d + max(lambda_max,k, 0) d^2/2) + T d^3/6
      ! with the sampled Hessian's eigenvalues and T = N^3 M >= |r'''| (Bernstein); the tighter
      ! of the two is kept
      body%third = real(n, wp)**3 * mm
      margin = 1.0e-11_wp * smax
      allocate (clo(ntg, npg), chi(ntg, npg), dcr(ntg))
      do ic = 1, ntg
         if ((ic - 1) * dth <= 0.5_wp * pi .and. ic * dth >= 0.5_wp * pi) then
            smx = 1.0_wp
         else
            smx = max(sin((ic - 1) * dth), sin(ic * dth))
         end if
         dc = 0.5_wp * (dth + smx * dph)
         dcr(ic) = dc
         do jc = 1, npg
            hi = max(rg(ic - 1, jc - 1) + gg(ic - 1, jc - 1) * dc, rg(ic, jc - 1) + gg(ic, jc - 1) * dc, &
                     rg(ic - 1, jc) + gg(ic - 1, jc) * dc, rg(ic, jc) + gg(ic, jc) * dc)
            lo = min(rg(ic - 1, jc - 1) - gg(ic - 1, jc - 1) * dc, rg(ic, jc - 1) - gg(ic, jc - 1) * dc, &
                     rg(ic - 1, jc) - gg(ic - 1, jc) * dc, rg(ic, jc) - gg(ic, jc) * dc)
            chi(ic, jc) = hi + 0.5_wp * body%curvature * dc**2
            clo(ic, jc) = lo - 0.5_wp * body%curvature * dc**2
            if (ic > 1 .and. ic < ntg) then
               hi = max(rg(ic - 1, jc - 1) + gg(ic - 1, jc - 1) * dc + 0.5_wp * qhi(ic - 1, jc - 1) * dc**2, &
                        rg(ic, jc - 1) + gg(ic, jc - 1) * dc + 0.5_wp * qhi(ic, jc - 1) * dc**2, &
                        rg(ic - 1, jc) + gg(ic - 1, jc) * dc + 0.5_wp * qhi(ic - 1, jc) * dc**2, &
                        rg(ic, jc) + gg(ic, jc) * dc + 0.5_wp * qhi(ic, jc) * dc**2)
               lo = min(rg(ic - 1, jc - 1) - gg(ic - 1, jc - 1) * dc + 0.5_wp * qlo(ic - 1, jc - 1) * dc**2, &
                        rg(ic, jc - 1) - gg(ic, jc - 1) * dc + 0.5_wp * qlo(ic, jc - 1) * dc**2, &
                        rg(ic - 1, jc) - gg(ic - 1, jc) * dc + 0.5_wp * qlo(ic - 1, jc) * dc**2, &
                        rg(ic, jc) - gg(ic, jc) * dc + 0.5_wp * qlo(ic, jc) * dc**2)
               chi(ic, jc) = min(chi(ic, jc), hi + body%third * dc**3 / 6.0_wp + margin)
               clo(ic, jc) = max(clo(ic, jc), lo - body%third * dc**3 / 6.0_wp - margin)
            end if
         end do
      end do
      ! deep levels: bounds only, rounded outwards to single precision
      nd = 0
      do l = leaf_level + 1, stored_level
         body%doff(l) = nd
         nd = nd + patch_rows(l) * patch_cols(l)
      end do
      body%doff(stored_level + 1) = nd
      allocate (body%dlo(nd), body%dhi(nd))
      do l = leaf_level + 1, stored_level
         kc = cells_per_leaf / 2**(l - leaf_level)
         do j = 1, patch_cols(l)
            do i = 1, patch_rows(l)
               k = body%doff(l) + (j - 1) * patch_rows(l) + i
               lo = minval(clo((i - 1) * kc + 1:i * kc, (j - 1) * kc + 1:j * kc))
               hi = maxval(chi((i - 1) * kc + 1:i * kc, (j - 1) * kc + 1:j * kc))
               body%dlo(k) = real(lo, sp)
               if (real(body%dlo(k), wp) > lo) body%dlo(k) = nearest(body%dlo(k), -1.0_sp)
               body%dhi(k) = real(hi, sp)
               if (real(body%dhi(k), wp) < hi) body%dhi(k) = nearest(body%dhi(k), 1.0_sp)
            end do
         end do
      end do
      ! row and column tables of every stored level
      allocate (body%row_ct(4 * (2**(stored_level + 1) - 1)), body%row_st(4 * (2**(stored_level + 1) - 1)), &
                body%row_cosa(4 * (2**(stored_level + 1) - 1)), body%row_sina(4 * (2**(stored_level + 1) - 1)), &
                body%col_cp(8 * (2**(stored_level + 1) - 1)), body%col_sp(8 * (2**(stored_level + 1) - 1)))
      do l = 0, stored_level
         body%roff(l) = 4 * (2**l - 1)
         body%coff(l) = 8 * (2**l - 1)
         do i = 1, patch_rows(l)
            call patch_cap(pi * (i - 1) / patch_rows(l), pi * i / patch_rows(l), 0.0_wp, two_pi / patch_cols(l), &
                           d3, body%row_cosa(body%roff(l) + i), body%row_sina(body%roff(l) + i))
            body%row_ct(body%roff(l) + i) = cos(pi * (i - 0.5_wp) / patch_rows(l))
            body%row_st(body%roff(l) + i) = sin(pi * (i - 0.5_wp) / patch_rows(l))
         end do
         do j = 1, patch_cols(l)
            body%col_cp(body%coff(l) + j) = cos(two_pi * (j - 0.5_wp) / patch_cols(l))
            body%col_sp(body%coff(l) + j) = sin(two_pi * (j - 0.5_wp) / patch_cols(l))
         end do
      end do
      ! patch storage
      np_tot = 0
      do l = 0, leaf_level
         body%off(l) = np_tot
         np_tot = np_tot + patch_rows(l) * patch_cols(l)
      end do
      body%off(leaf_level + 1) = np_tot
      allocate (body%dir(3, np_tot), body%cosa(np_tot), body%sina(np_tot), body%rlo(np_tot), body%rhi(np_tot), &
                body%ball(3, np_tot), body%brad(np_tot))
      do l = leaf_level, 0, -1
         kc = cells_per_leaf * 2**(leaf_level - l)
         do j = 1, patch_cols(l)
            do i = 1, patch_rows(l)
               k = patch_index(body, l, i, j)
               if (l == leaf_level) then
                  body%rlo(k) = minval(clo((i - 1) * kc + 1:i * kc, (j - 1) * kc + 1:j * kc))
                  body%rhi(k) = maxval(chi((i - 1) * kc + 1:i * kc, (j - 1) * kc + 1:j * kc))
               else
                  body%rlo(k) = min(body%rlo(patch_index(body, l + 1, 2 * i - 1, 2 * j - 1)), &
                                    body%rlo(patch_index(body, l + 1, 2 * i, 2 * j - 1)), &
                                    body%rlo(patch_index(body, l + 1, 2 * i - 1, 2 * j)), &
                                    body%rlo(patch_index(body, l + 1, 2 * i, 2 * j)))
                  body%rhi(k) = max(body%rhi(patch_index(body, l + 1, 2 * i - 1, 2 * j - 1)), &
                                    body%rhi(patch_index(body, l + 1, 2 * i, 2 * j - 1)), &
                                    body%rhi(patch_index(body, l + 1, 2 * i - 1, 2 * j)), &
                                    body%rhi(patch_index(body, l + 1, 2 * i, 2 * j)))
               end if
               call patch_cap(pi * (i - 1) / patch_rows(l), pi * i / patch_rows(l), &
                              two_pi * (j - 1) / patch_cols(l), two_pi * j / patch_cols(l), &
                              body%dir(:, k), body%cosa(k), body%sina(k))
               call sector_ball(body%dir(:, k), body%cosa(k), body%sina(k), body%rlo(k), body%rhi(k), &
                                body%ball(:, k), body%brad(k))
            end do
         end do
      end do
      body%r_max = maxval(body%rhi(body%off(0) + 1:body%off(1)))
      body%r_min = minval(body%rlo(body%off(0) + 1:body%off(1)))
      if (body%r_min <= 0.0_wp) then
         call fatal_error(error, "contact body: shape is not certified star-shaped (r_min bound " &
                          //to_string(body%r_min)//" <= 0)", error_code%not_star)
         return
      end if
      ! guaranteed box from the leaf sectors: max of x.e over a sector <= rho_max(u.e) * max_cap(u.e)
      body%box_lo = huge(1.0_wp)
      body%box_hi = -huge(1.0_wp)
      do k = body%off(leaf_level) + 1, body%off(leaf_level + 1)
         do i = 1, 3
            e = 0.0_wp
            do j = -1, 1, 2
               e(i) = real(j, wp)
               ang = acos(max(-1.0_wp, min(1.0_wp, dot_product(body%dir(:, k), e)))) - atan2(body%sina(k), body%cosa(k))
               mu = cos(max(0.0_wp, ang))
               if (mu >= 0.0_wp) then
                  hi = body%rhi(k) * mu
               else
                  hi = body%rlo(k) * mu
               end if
               if (j > 0) then
                  body%box_hi(i) = max(body%box_hi(i), hi)
               else
                  body%box_lo(i) = min(body%box_lo(i), -hi)
               end if
            end do
         end do
      end do
      call surface_boxes(body, ntg, npg, rg, rt, rp, h11, h12, h22, dcr)
      call extent_scan(body%shape, body%next, body%ext_lo, body%ext_hi)
   end subroutine new_contact_body

   !> Oriented boxes of the surface pieces of the patches of levels 0..leaf_level. The frame of a
   !> patch is the surface normal n at its centre (a grid point) and two tangents. For a unit
   !> vector e, f(u) = e . (r(u) u) restricted to a unit-speed great circle is f = r w with
   !> w = e . u, w'' = -w and w^2 + w'^2 <= 1, so (Cauchy-Schwarz, with the Bernstein bounds
   !> G >= |r'|, H >= |r''|, T >= |r'''|)
   !>     f'' = (r'' - r) w + 2 r' w',              |f''| <= H_f = sqrt((H + r_max)^2 + 4 G^2),
   !>     f''' = (r''' - 3 r') w + (3 r'' - r) w',  |f'''| <= T_f = sqrt((T + 3 G)^2 + (3 H + r_max)^2).
   !> Every point of a grid cell is within d_c of a corner k along a great circle, so over the cell
   !>     f <= max_k (f_k + |grad f_k| d_c) + H_f d_c^2/2   (first order), and
   !>     f <= max_k (f_k + |grad f_k| d_c + max(lambda_max(Hess f_k), 0) d_c^2/2) + T_f d_c^3/6
   !> (second order, patches off the poles), symmetrically for the minimum; the tighter is kept.
   !> In the frame (e_theta, e_phi), with g = (r_theta, r_phi/sin theta) and h the covariant
   !> Hessian of r: grad f_i = g_i (e . u) + r (e . e_i) and
   !>     Hess f_ij = (h_ij - r delta_ij)(e . u) + g_i (e . e_j) + g_j (e . e_i).
   !> Leaf patches take these bounds over their grid points; coarser patches bound the boxes of
   !> their four children along their own axes. Rounding margins of 1e-11 r_max are added.
   pure subroutine surface_boxes(body, ntg, npg, rg, rt, rp, h11, h12, h22, dcr)
      type(contact_body_type), intent(inout) :: body
      integer, intent(in) :: ntg, npg
      !> r, its gradient (dr/dtheta, (dr/dphi)/sin(theta)), its covariant Hessian on the grid;
      !> d_c per cell row.
      real(wp), intent(in) :: rg(0:, 0:), rt(0:, 0:), rp(0:, 0:), h11(0:, 0:), h12(0:, 0:), h22(0:, 0:), dcr(:)
      real(wp), allocatable :: st(:), ct(:), sp(:), cp(:)
      real(wp) :: hf, tf, d, e(3, 3), lo(3), hi(3), lo2(3), hi2(3), x(3), xt(3), xp(3), eph(3), pc, pr, margin
      real(wp) :: u(3), et(3), ep(3), eu, eet, eep, g1, g2, g, a11, a12, a22, am, ar, r
      real(wp), allocatable :: obb_c(:, :), obb_e(:, :, :), obb_h(:, :)
      integer :: l, i, j, k, kc, ig, jg, i0, j0, m, di, dj, kch, np
      logical :: second
      allocate (st(0:ntg), ct(0:ntg), sp(0:npg), cp(0:npg))
      do ig = 0, ntg
         st(ig) = sin(pi * ig / ntg)
         ct(ig) = cos(pi * ig / ntg)
      end do
      do jg = 0, npg
         sp(jg) = sin(two_pi * mod(jg, npg) / npg)
         cp(jg) = cos(two_pi * mod(jg, npg) / npg)
      end do
      hf = sqrt((body%curvature + body%r_max)**2 + 4.0_wp * body%lipschitz**2)
      tf = sqrt((body%third + 3.0_wp * body%lipschitz)**2 + (3.0_wp * body%curvature + body%r_max)**2)
      margin = 1.0e-11_wp * body%r_max
      np = body%off(leaf_level + 1)
      allocate (obb_c(3, np), obb_e(3, 3, np), obb_h(3, np), body%node(node_size, np))
      do l = leaf_level, 0, -1
         kc = cells_per_leaf * 2**(leaf_level - l)
         do j = 1, patch_cols(l)
            do i = 1, patch_rows(l)
               k = patch_index(body, l, i, j)
               ! frame: normal at the centre grid point
               ig = (i - 1) * kc + kc / 2
               jg = (j - 1) * kc + kc / 2
               call grid_point(ig, jg, x, xt, xp)
               body%node(nd_rc, k) = rg(ig, jg)
               e(:, 3) = cross(xt, xp)
               e(:, 3) = e(:, 3) / norm2(e(:, 3))
               eph = [-sp(jg), cp(jg), 0.0_wp]
               e(:, 1) = eph - dot_product(eph, e(:, 3)) * e(:, 3)
               e(:, 1) = e(:, 1) / norm2(e(:, 1))
               e(:, 2) = cross(e(:, 3), e(:, 1))
               lo = huge(1.0_wp)
               hi = -huge(1.0_wp)
               if (l == leaf_level) then
                  i0 = (i - 1) * kc
                  j0 = (j - 1) * kc
                  d = maxval(dcr(i0 + 1:i0 + kc))
                  second = i0 > 0 .and. i0 + kc < ntg
                  lo2 = huge(1.0_wp)
                  hi2 = -huge(1.0_wp)
                  do jg = j0, j0 + kc
                     do ig = i0, i0 + kc
                        u = [st(ig) * cp(jg), st(ig) * sp(jg), ct(ig)]
                        et = [ct(ig) * cp(jg), ct(ig) * sp(jg), -st(ig)]
                        ep = [-sp(jg), cp(jg), 0.0_wp]
                        r = rg(ig, jg)
                        do m = 1, 3
                           eu = dot_product(e(:, m), u)
                           eet = dot_product(e(:, m), et)
                           eep = dot_product(e(:, m), ep)
                           g1 = rt(ig, jg) * eu + r * eet
                           g2 = rp(ig, jg) * eu + r * eep
                           g = sqrt(g1**2 + g2**2)
                           lo(m) = min(lo(m), r * eu - g * d)
                           hi(m) = max(hi(m), r * eu + g * d)
                           if (second) then
                              a11 = (h11(ig, jg) - r) * eu + 2.0_wp * rt(ig, jg) * eet
                              a12 = h12(ig, jg) * eu + rt(ig, jg) * eep + rp(ig, jg) * eet
                              a22 = (h22(ig, jg) - r) * eu + 2.0_wp * rp(ig, jg) * eep
                              am = 0.5_wp * (a11 + a22)
                              ar = sqrt((0.5_wp * (a11 - a22))**2 + a12**2)
                              lo2(m) = min(lo2(m), r * eu - g * d + 0.5_wp * min(0.0_wp, am - ar) * d**2)
                              hi2(m) = max(hi2(m), r * eu + g * d + 0.5_wp * max(0.0_wp, am + ar) * d**2)
                           end if
                        end do
                     end do
                  end do
                  lo = lo - 0.5_wp * hf * d**2
                  hi = hi + 0.5_wp * hf * d**2
                  if (second) then
                     lo = max(lo, lo2 - tf * d**3 / 6.0_wp)
                     hi = min(hi, hi2 + tf * d**3 / 6.0_wp)
                  end if
               else
                  do dj = 0, 1
                     do di = 0, 1
                        kch = patch_index(body, l + 1, 2 * i - 1 + di, 2 * j - 1 + dj)
                        do m = 1, 3
                           pc = dot_product(e(:, m), obb_c(:, kch))
                           pr = sum(obb_h(:, kch) * abs(matmul(e(:, m), obb_e(:, :, kch))))
                           lo(m) = min(lo(m), pc - pr)
                           hi(m) = max(hi(m), pc + pr)
                        end do
                     end do
                  end do
               end if
               obb_c(:, k) = matmul(e, 0.5_wp * (lo + hi))
               obb_e(:, :, k) = e
               obb_h(:, k) = 0.5_wp * (hi - lo) + margin
            end do
         end do
      end do
      do k = 1, np
         body%node(nd_dir:nd_dir + 2, k) = body%dir(:, k)
         body%node(nd_cosa, k) = body%cosa(k)
         body%node(nd_sina, k) = body%sina(k)
         body%node(nd_c:nd_c + 2, k) = obb_c(:, k)
         body%node(nd_r, k) = norm2(obb_h(:, k)) * (1.0_wp + 1.0e-12_wp)
         body%node(nd_e:nd_e + 8, k) = reshape(obb_e(:, :, k), [9])
         body%node(nd_h:nd_h + 2, k) = obb_h(:, k)
         body%node(nd_ball:nd_ball + 2, k) = body%ball(:, k)
         body%node(nd_brad, k) = body%brad(k)
      end do
   contains
      pure subroutine grid_point(ig, jg, x, xt, xp)
         integer, intent(in) :: ig, jg
         real(wp), intent(out) :: x(3), xt(3), xp(3)
         real(wp) :: u(3), eth(3), eph(3)
         u = [st(ig) * cp(jg), st(ig) * sp(jg), ct(ig)]
         eth = [ct(ig) * cp(jg), ct(ig) * sp(jg), -st(ig)]
         eph = [-sp(jg), cp(jg), 0.0_wp]
         x = rg(ig, jg) * u
         xt = rt(ig, jg) * u + rg(ig, jg) * eth
         xp = rp(ig, jg) * u + rg(ig, jg) * eph
      end subroutine grid_point
   end subroutine surface_boxes

   !> Cross product.
   pure function cross(a, b) result(c)
      real(wp), intent(in) :: a(3), b(3)
      real(wp) :: c(3)
      c = [a(2) * b(3) - a(3) * b(2), a(3) * b(1) - a(1) * b(3), a(1) * b(2) - a(2) * b(1)]
   end function cross

   !> r and its angular derivatives on the regular grid theta_i = i pi/nt (i = 0..nt),
   !> phi_j = 2 pi j/np (j = 0..np, column np repeating column 0): per ring the sums over degree,
   !> then per azimuth the sums over order with a cos/sin table. Outputs r, the gradient in the
   !> orthonormal frame (e_theta, e_phi), (dr/dtheta, (dr/dphi)/sin theta), and the covariant
   !> Hessian in that frame, h11 = r_theta,theta, h12 = (r_theta,phi - cot(theta) r_phi)/sin theta,
   !> h22 = r_phi,phi/sin^2 theta + cot(theta) r_theta (zero on the pole rows i = 0, nt); the
   !> Legendre equation gives h11 + h22 = -sum n(n+1) a_nm Y_nm.
   pure subroutine synthesize_regular(shape, nt, np, r, rt, rp, h11, h12, h22)
      type(sh_expansion_type), intent(in) :: shape
      integer, intent(in) :: nt, np
      real(wp), intent(out) :: r(0:nt, 0:np), rt(0:nt, 0:np), rp(0:nt, 0:np), h11(0:nt, 0:np), h12(0:nt, 0:np), &
                               h22(0:nt, 0:np)
      real(wp), allocatable :: p(:), dp(:), mps(:), cs(:, :), sn(:, :)
      real(wp), allocatable :: ca(:), cb(:), da(:), db(:), ea(:), eb(:), la(:), lb(:)
      integer, allocatable :: idx_out(:)
      integer :: nmax, i, j, m, n, k
      real(wp) :: th, vr, vt, vp, vl, vpp, vtp, st, ct, q

      nmax = shape%nmax
      allocate (p(packed_size(nmax + 1)), dp(packed_size(nmax)), mps(packed_size(nmax)), idx_out(0:nmax))
      allocate (cs(0:nmax, 0:np), sn(0:nmax, 0:np), ca(0:nmax), cb(0:nmax), da(0:nmax), db(0:nmax), &
                ea(0:nmax), eb(0:nmax), la(0:nmax), lb(0:nmax))
      k = 1
      do m = 0, nmax
         idx_out(m) = k
         k = k + nmax - m + 1
      end do
      do j = 0, np
         do m = 0, nmax
            cs(m, j) = cos(m * two_pi * mod(j, np) / np)
            sn(m, j) = sin(m * two_pi * mod(j, np) / np)
         end do
      end do
      do i = 0, nt
         th = pi * i / nt
         st = sin(th)
         ct = cos(th)
         call legendre_values(shape%table, ct, p, st)
         call legendre_theta_derivatives(shape%table, p, nmax, idx_out, dp, mps)
         do m = 0, nmax
            ca(m) = 0.0_wp
            cb(m) = 0.0_wp
            da(m) = 0.0_wp
            db(m) = 0.0_wp
            ea(m) = 0.0_wp
            eb(m) = 0.0_wp
            la(m) = 0.0_wp
            lb(m) = 0.0_wp
            do n = m, nmax
               q = p(shape%table%idx(m) + n - m)
               ca(m) = ca(m) + shape%a(n, m) * q
               cb(m) = cb(m) + shape%b(n, m) * q
               la(m) = la(m) + shape%a(n, m) * (n * (n + 1) * q)
               lb(m) = lb(m) + shape%b(n, m) * (n * (n + 1) * q)
               da(m) = da(m) + shape%a(n, m) * dp(idx_out(m) + n - m)
               db(m) = db(m) + shape%b(n, m) * dp(idx_out(m) + n - m)
               ea(m) = ea(m) + shape%a(n, m) * mps(idx_out(m) + n - m)
               eb(m) = eb(m) + shape%b(n, m) * mps(idx_out(m) + n - m)
            end do
         end do
         do j = 0, np
            vr = 0.0_wp
            vt = 0.0_wp
            vp = 0.0_wp
            vl = 0.0_wp
            vpp = 0.0_wp
            vtp = 0.0_wp
            do m = 0, nmax
               vr = vr + ca(m) * cs(m, j) + cb(m) * sn(m, j)
               vt = vt + da(m) * cs(m, j) + db(m) * sn(m, j)
               vp = vp + eb(m) * cs(m, j) - ea(m) * sn(m, j)
               vl = vl + la(m) * cs(m, j) + lb(m) * sn(m, j)
               vpp = vpp + m * (ea(m) * cs(m, j) + eb(m) * sn(m, j))
               vtp = vtp + m * (db(m) * cs(m, j) - da(m) * sn(m, j))
            end do
            r(i, j) = vr
            rt(i, j) = vt
            rp(i, j) = vp
            if (i == 0 .or. i == nt) then
               h11(i, j) = 0.0_wp
               h12(i, j) = 0.0_wp
               h22(i, j) = 0.0_wp
            else
               ! r_phi,phi / sin^2 = -sum m (m A_m / sin) (cos, sin) / sin; r_theta,phi / sin likewise
               h22(i, j) = (-vpp + ct * vt) / st
               h11(i, j) = -vl - h22(i, j)
               h12(i, j) = (vtp - ct * vp) / st
            end if
         end do
      end do
   end subroutine synthesize_regular
end module anm_contact_body
