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
   use anm_geometry_radial_bound, only: radial_bound_type
   implicit none
   private

   public :: contact_body_type, new_contact_body, leaf_level, stored_level, patch_rows, patch_cols, patch_index, &
      & patch_cap, sector_ball, default_next, patch_geometry, patch_bounds, slope_bound, support_bound, support_cell, &
      & add_support_table, radial_bound
   public :: node_size, nd_dir, nd_cosa, nd_sina, nd_c, nd_r, nd_e, nd_h, nd_ball, nd_brad, nd_rc

   !> Finest stored patch level (64 x 128 patches of pi/64 rad).
   integer, parameter :: leaf_level = 4
   !> Finest level with stored bounds (256 x 512 patches of pi/256 rad, 2 x 2 certification cells).
   integer, parameter :: stored_level = 6
   !> Grid cells per leaf patch edge used to certify the bounds.
   integer, parameter :: cells_per_leaf = 8
   !> Thesis default N_ext.
   integer, parameter :: default_next = 40
   !> Cells per face edge of the cube map of directions of the support table (6 x 32^2 cells of
   !> about 0.05 rad).
   integer, parameter :: support_n = 32

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
      !> Support table (4, 6 support_n^2): for each cell of a cube map of directions
      !> (`support_cell`), a surface point x0 (rows 1-3) and eps (row 4, rounded up) such that the
      !> support function h(v) = max x . v over the surface points x is at most x0 . v + eps for
      !> every unit v of the cell (shape units; `support_bound`). Built with the patch arrays
      !> unless new_contact_body is told not to (`add_support_table` later), dropped with them;
      !> the contact test uses it when both bodies have one and gives the same answers without.
      real(sp), allocatable :: supp(:, :)
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
   !> Pass 1 samples r on the whole certification grid (for the certified bound M); pass 2 goes
   !> through the grid one leaf row (8 cell rows) at a time, sampling the derivatives of r there,
   !> and sets the cell bounds, the stored bounds of the leaf and deeper patches and the leaf
   !> boxes of that row; coarser patches follow from their children. The support table last
   !> (about a third of the time at order 14), unless `table` is false.
   subroutine new_contact_body(body, shape, error, nused, next, table)
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
      !> Whether the support table is built (default true; `add_support_table` builds it later).
      logical, intent(in), optional :: table
      integer, parameter :: kb = cells_per_leaf
      real(wp), allocatable :: rg(:, :), rt(:, :), rp(:, :), h11(:, :), h12(:, :), h22(:, :), clo(:, :), chi(:, :), &
                               dcr(:), obb_c(:, :), obb_e(:, :, :), obb_h(:, :), trig(:, :), bv(:, :, :), w(:, :)
      integer :: ntg, npg, nleaf_t, nleaf_p, i, j, l, k, n, np_tot, kc, nd, ip, i0, nr
      real(wp) :: dth, dph, smin, smax, ms, dmax, mm, smx, hi, lo, margin, rbound
      logical :: with_table

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
      ! pass 1: r on the grid and the certified bounds of its derivatives along great circles
      allocate (rg(0:ntg, 0:npg))
      call synthesize_rows(body%shape, npg, ntg, 0, ntg, rg)
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
      body%third = real(n, wp)**3 * mm
      ! |r| <= |c| + M with c the mid value
      rbound = abs(0.5_wp * (smax + smin)) + mm
      margin = 1.0e-11_wp * smax
      ! d_c per cell row: every point of a cell is within d_c of a corner along a great circle
      allocate (dcr(ntg))
      do i = 1, ntg
         if ((i - 1) * dth <= 0.5_wp * pi .and. i * dth >= 0.5_wp * pi) then
            smx = 1.0_wp
         else
            smx = max(sin((i - 1) * dth), sin(i * dth))
         end if
         dcr(i) = 0.5_wp * (dth + smx * dph)
      end do
      call grid_trig(ntg, npg, trig)
      call storage_offsets(body, nd, np_tot)
      allocate (body%dlo(nd), body%dhi(nd), body%dir(3, np_tot), body%cosa(np_tot), body%sina(np_tot), &
                body%rlo(np_tot), body%rhi(np_tot), body%ball(3, np_tot), body%brad(np_tot), &
                body%node(node_size, np_tot), obb_c(3, np_tot), obb_e(3, 3, np_tot), obb_h(3, np_tot))
      ! pass 2, one leaf row at a time
      allocate (rt(0:kb, 0:npg), rp(0:kb, 0:npg), h11(0:kb, 0:npg), h12(0:kb, 0:npg), h22(0:kb, 0:npg), &
                clo(kb, npg), chi(kb, npg), bv(0:kb, 0:npg, 18), w((kb + 1)**2, 18))
      do ip = 1, nleaf_t
         i0 = (ip - 1) * kb
         call synthesize_rows(body%shape, npg, ntg, i0, i0 + kb, rt=rt, rp=rp, h11=h11, h12=h12, h22=h22)
         call cell_bounds(body, rg(i0:i0 + kb, :), rt, rp, h11, h12, h22, dcr(i0 + 1:i0 + kb), i0 == 0, &
                          i0 + kb == ntg, margin, clo, chi)
         call band_vectors(i0, trig, rg(i0:i0 + kb, :), rt, rp, h11, h12, h22, bv)
         ! leaf patches of this row and the deeper stored levels (rounded outwards to single)
         do j = 1, nleaf_p
            k = patch_index(body, leaf_level, ip, j)
            body%rlo(k) = minval(clo(:, (j - 1) * kb + 1:j * kb))
            body%rhi(k) = maxval(chi(:, (j - 1) * kb + 1:j * kb))
            do l = 1, 18
               do i = 0, kb
                  w(i * (kb + 1) + 1:(i + 1) * (kb + 1), l) = bv(:, (j - 1) * kb + i, l)
               end do
            end do
            call leaf_box(body, w, i0 > 0 .and. i0 + kb < ntg, maxval(dcr(i0 + 1:i0 + kb)), rbound, margin, &
                          obb_c(:, k), obb_e(:, :, k), obb_h(:, k))
            body%node(nd_rc, k) = rg(i0 + kb / 2, (j - 1) * kb + kb / 2)
         end do
         do l = leaf_level + 1, stored_level
            kc = cells_per_leaf / 2**(l - leaf_level)
            nr = 2**(l - leaf_level)
            do j = 1, patch_cols(l)
               do i = 1, nr
                  k = body%doff(l) + (j - 1) * patch_rows(l) + (ip - 1) * nr + i
                  lo = minval(clo((i - 1) * kc + 1:i * kc, (j - 1) * kc + 1:j * kc))
                  hi = maxval(chi((i - 1) * kc + 1:i * kc, (j - 1) * kc + 1:j * kc))
                  body%dlo(k) = real(lo, sp)
                  if (real(body%dlo(k), wp) > lo) body%dlo(k) = nearest(body%dlo(k), -1.0_sp)
                  body%dhi(k) = real(hi, sp)
                  if (real(body%dhi(k), wp) < hi) body%dhi(k) = nearest(body%dhi(k), 1.0_sp)
               end do
            end do
         end do
      end do
      call row_column_tables(body)
      ! coarser patches from their children; caps and sector balls of every stored-cap level
      do l = leaf_level, 0, -1
         kc = cells_per_leaf * 2**(leaf_level - l)
         do j = 1, patch_cols(l)
            do i = 1, patch_rows(l)
               k = patch_index(body, l, i, j)
               if (l < leaf_level) then
                  body%rlo(k) = min(body%rlo(patch_index(body, l + 1, 2 * i - 1, 2 * j - 1)), &
                                    body%rlo(patch_index(body, l + 1, 2 * i, 2 * j - 1)), &
                                    body%rlo(patch_index(body, l + 1, 2 * i - 1, 2 * j)), &
                                    body%rlo(patch_index(body, l + 1, 2 * i, 2 * j)))
                  body%rhi(k) = max(body%rhi(patch_index(body, l + 1, 2 * i - 1, 2 * j - 1)), &
                                    body%rhi(patch_index(body, l + 1, 2 * i, 2 * j - 1)), &
                                    body%rhi(patch_index(body, l + 1, 2 * i - 1, 2 * j)), &
                                    body%rhi(patch_index(body, l + 1, 2 * i, 2 * j)))
                  call parent_box(body, l, i, j, obb_c, obb_e, obb_h, margin)
                  body%node(nd_rc, k) = rg((i - 1) * kc + kc / 2, (j - 1) * kc + kc / 2)
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
      call fill_nodes(body, obb_c, obb_e, obb_h)
      with_table = .true.
      if (present(table)) with_table = table
      if (with_table) call support_table(body)
      call guaranteed_box(body)
      call extent_scan(body%shape, body%next, body%ext_lo, body%ext_hi)
   end subroutine new_contact_body

   !> Build the support table of a body that has its patch arrays but no table yet (nothing
   !> otherwise): the contact test's answers do not change, only how soon the easy ones come.
   pure subroutine add_support_table(body)
      !> Body built by new_contact_body(..., table=.false.).
      type(contact_body_type), intent(inout) :: body
      if (allocated(body%node) .and. .not. allocated(body%supp)) call support_table(body)
   end subroutine add_support_table

   !> Sines and cosines of the grid's polar angles pi i/ntg (rows 1, 2) and azimuths 2 pi j/npg
   !> (rows 3, 4).
   pure subroutine grid_trig(ntg, npg, trig)
      !> Polar and azimuthal intervals of the grid.
      integer, intent(in) :: ntg, npg
      !> Table (4, 0:max(ntg, npg)).
      real(wp), allocatable, intent(out) :: trig(:, :)
      integer :: i, j
      allocate (trig(4, 0:max(ntg, npg)))
      do i = 0, ntg
         trig(1, i) = sin(pi * i / ntg)
         trig(2, i) = cos(pi * i / ntg)
      end do
      do j = 0, npg
         trig(3, j) = sin(two_pi * mod(j, npg) / npg)
         trig(4, j) = cos(two_pi * mod(j, npg) / npg)
      end do
   end subroutine grid_trig

   !> Offsets of the stored levels in the packed patch arrays (`doff`: the deeper bound levels,
   !> nd entries; `off`: the cap levels 0..leaf_level, np_tot patches).
   pure subroutine storage_offsets(body, nd, np_tot)
      !> Contact body being built.
      type(contact_body_type), intent(inout) :: body
      !> Number of stored bounds and of patches.
      integer, intent(out) :: nd, np_tot
      integer :: l
      nd = 0
      do l = leaf_level + 1, stored_level
         body%doff(l) = nd
         nd = nd + patch_rows(l) * patch_cols(l)
      end do
      body%doff(stored_level + 1) = nd
      np_tot = 0
      do l = 0, leaf_level
         body%off(l) = np_tot
         np_tot = np_tot + patch_rows(l) * patch_cols(l)
      end do
      body%off(leaf_level + 1) = np_tot
   end subroutine storage_offsets

   !> Row and column tables (cap cosines, centre sines and cosines) of every stored level.
   pure subroutine row_column_tables(body)
      !> Contact body being built.
      type(contact_body_type), intent(inout) :: body
      integer :: l, i, j
      real(wp) :: d3(3)
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
   end subroutine row_column_tables

   !> The node records (the patch data a contact test touches) from the patch arrays and the
   !> patches' bounding boxes (centre, axes, half-widths).
   pure subroutine fill_nodes(body, obb_c, obb_e, obb_h)
      !> Contact body being built.
      type(contact_body_type), intent(inout) :: body
      !> Box centres (3, np), axes (3, 3, np) and half-widths (3, np) of the patches.
      real(wp), intent(in) :: obb_c(:, :), obb_e(:, :, :), obb_h(:, :)
      integer :: k
      do k = 1, size(body%dir, 2)
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
   end subroutine fill_nodes

   !> Guaranteed box of the body from the leaf sectors: max of x.e over a sector
   !> <= rho_max(u.e) * max_cap(u.e).
   pure subroutine guaranteed_box(body)
      !> Contact body being built.
      type(contact_body_type), intent(inout) :: body
      integer :: k, i, j
      real(wp) :: e(3), ang, mu, hi
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
   end subroutine guaranteed_box

   !> Certified bounds of r over the cells of one leaf row (grid rows 0..kb of the band). First
   !> order with the Bernstein curvature H = N^2 M:
   !>     r <= max_k (r_k + |grad r_k| d_c) + H d_c^2/2   (k the cell corners);
   !> second order (cells not touching a pole) with the sampled Hessian and T = N^3 M >= |r'''|:
   !>     r <= max_k (r_k + |grad r_k| d_c + max(lambda_max(Hess r_k), 0) d_c^2/2) + T d_c^3/6,
   !> symmetrically for the minimum; the tighter of the two is kept.
   pure subroutine cell_bounds(body, rg, rt, rp, h11, h12, h22, dcr, north, south, margin, clo, chi)
      type(contact_body_type), intent(in) :: body
      !> r, gradient and Hessian on the band's grid rows (0:kb, 0:npg).
      real(wp), intent(in) :: rg(0:, 0:), rt(0:, 0:), rp(0:, 0:), h11(0:, 0:), h12(0:, 0:), h22(0:, 0:)
      !> d_c of the band's cell rows.
      real(wp), intent(in) :: dcr(:)
      !> The band's first (last) grid row is the north (south) pole.
      logical, intent(in) :: north, south
      !> Rounding margin.
      real(wp), intent(in) :: margin
      !> Lower and upper bounds per cell (kb, npg).
      real(wp), intent(out) :: clo(:, :), chi(:, :)
      real(wp), allocatable :: g(:, :), qhi(:, :), qlo(:, :)
      real(wp) :: dc, hi, lo, c2, c3
      integer :: ic, jc, kb, npg, a, b
      kb = size(clo, 1)
      npg = size(clo, 2)
      allocate (g(0:kb, 0:npg), qhi(0:kb, 0:npg), qlo(0:kb, 0:npg))
      g(:, :) = sqrt(rt**2 + rp**2)
      ! largest and smallest eigenvalue of the Hessian, clipped at 0
      qhi(:, :) = max(0.0_wp, 0.5_wp * (h11 + h22) + sqrt((0.5_wp * (h11 - h22))**2 + h12**2))
      qlo(:, :) = min(0.0_wp, 0.5_wp * (h11 + h22) - sqrt((0.5_wp * (h11 - h22))**2 + h12**2))
      do ic = 1, kb
         dc = dcr(ic)
         c2 = 0.5_wp * body%curvature * dc**2
         c3 = body%third * dc**3 / 6.0_wp + margin
         do jc = 1, npg
            hi = -huge(1.0_wp)
            lo = huge(1.0_wp)
            do b = jc - 1, jc
               do a = ic - 1, ic
                  hi = max(hi, rg(a, b) + g(a, b) * dc)
                  lo = min(lo, rg(a, b) - g(a, b) * dc)
               end do
            end do
            chi(ic, jc) = hi + c2
            clo(ic, jc) = lo - c2
            if ((ic > 1 .or. .not. north) .and. (ic < kb .or. .not. south)) then
               hi = -huge(1.0_wp)
               lo = huge(1.0_wp)
               do b = jc - 1, jc
                  do a = ic - 1, ic
                     hi = max(hi, rg(a, b) + g(a, b) * dc + 0.5_wp * qhi(a, b) * dc**2)
                     lo = min(lo, rg(a, b) - g(a, b) * dc + 0.5_wp * qlo(a, b) * dc**2)
                  end do
               end do
               chi(ic, jc) = min(chi(ic, jc), hi + c3)
               clo(ic, jc) = max(clo(ic, jc), lo - c3)
            end if
         end do
      end do
   end subroutine cell_bounds

   !> Oriented box of the surface piece of a leaf patch from its (kb+1) x (kb+1) grid points.
   !> The frame is the surface normal n at the patch centre (a grid point) and two tangents. For
   !> a unit vector e, f(u) = e . (r(u) u) restricted to a unit-speed great circle is f = r w with
   !> w = e . u, w'' = -w and w^2 + w'^2 <= 1, so (Cauchy-Schwarz, with the Bernstein bounds
   !> G >= |r'|, H >= |r''|, T >= |r'''|)
   !>     f'' = (r'' - r) w + 2 r' w',              |f''| <= H_f = sqrt((H + r_max)^2 + 4 G^2),
   !>     f''' = (r''' - 3 r') w + (3 r'' - r) w',  |f'''| <= T_f = sqrt((T + 3 G)^2 + (3 H + r_max)^2)
   !> (r_max here any bound of |r|). Every point of a grid cell is within d_c of a corner k along
   !> a great circle, so over the cell
   !>     f <= max_k (f_k + |grad f_k| d_c) + H_f d_c^2/2   (first order), and
   !>     f <= max_k (f_k + |grad f_k| d_c + max(lambda_max(Hess f_k), 0) d_c^2/2) + T_f d_c^3/6
   !> (second order, patches off the poles), symmetrically for the minimum; the tighter is kept.
   !> With g = (r_theta, r_phi/sin theta) and h the covariant Hessian of r in the frame
   !> (e_theta, e_phi): grad f_i = e . X_i with X_1 = r_theta u + r e_theta,
   !> X_2 = r_phi/sin theta u + r e_phi, and Hess f_ij = e . Y_ij with
   !> Y_ij = (h_ij - r delta_ij) u + g_i e_j + g_j e_i (`band_vectors`).
   pure subroutine leaf_box(body, w, second, d, rbound, margin, c, e, h)
      type(contact_body_type), intent(in) :: body
      !> The patch's grid points (kb+1)^2 of `band_vectors`: x (1:3), X_1 (4:6), X_2 (7:9),
      !> Y_11 (10:12), Y_12 (13:15), Y_22 (16:18).
      real(wp), intent(in) :: w(:, :)
      !> Second order allowed (the patch does not touch a pole).
      logical, intent(in) :: second
      !> Largest d_c of the patch's cells, bound of |r|, rounding margin.
      real(wp), intent(in) :: d, rbound, margin
      !> Box centre, axes (columns), half-extents.
      real(wp), intent(out) :: c(3), e(3, 3), h(3)
      integer :: npt, q, m, ic
      real(wp) :: hf, tf, lo(3), hi(3), lo2, hi2, f, g1, g2, g, a11, a12, a22, am, ar, e1, e2, e3, q2(3), u(3)
      npt = size(w, 1)
      hf = sqrt((body%curvature + rbound)**2 + 4.0_wp * body%lipschitz**2)
      tf = sqrt((body%third + 3.0_wp * body%lipschitz)**2 + (3.0_wp * body%curvature + rbound)**2)
      ! frame: normal at the centre grid point, X_1 x X_2
      ic = (npt + 1) / 2
      u = w(ic, 1:3) / norm2(w(ic, 1:3))
      e = frame(cross(w(ic, 4:6), w(ic, 7:9)), u, w(ic, 4:6) - dot_product(w(ic, 4:6), u) * u, &
                w(ic, 7:9) - dot_product(w(ic, 7:9), u) * u)
      do m = 1, 3
         e1 = e(1, m)
         e2 = e(2, m)
         e3 = e(3, m)
         lo(m) = huge(1.0_wp)
         hi(m) = -huge(1.0_wp)
         lo2 = huge(1.0_wp)
         hi2 = -huge(1.0_wp)
         if (second) then
            do q = 1, npt
               f = e1 * w(q, 1) + e2 * w(q, 2) + e3 * w(q, 3)
               g1 = e1 * w(q, 4) + e2 * w(q, 5) + e3 * w(q, 6)
               g2 = e1 * w(q, 7) + e2 * w(q, 8) + e3 * w(q, 9)
               g = sqrt(g1 * g1 + g2 * g2) * d
               a11 = e1 * w(q, 10) + e2 * w(q, 11) + e3 * w(q, 12)
               a12 = e1 * w(q, 13) + e2 * w(q, 14) + e3 * w(q, 15)
               a22 = e1 * w(q, 16) + e2 * w(q, 17) + e3 * w(q, 18)
               am = 0.5_wp * (a11 + a22)
               ar = sqrt(0.25_wp * (a11 - a22)**2 + a12 * a12)
               lo(m) = min(lo(m), f - g)
               hi(m) = max(hi(m), f + g)
               lo2 = min(lo2, f - g + 0.5_wp * min(0.0_wp, am - ar) * d**2)
               hi2 = max(hi2, f + g + 0.5_wp * max(0.0_wp, am + ar) * d**2)
            end do
         else
            do q = 1, npt
               f = e1 * w(q, 1) + e2 * w(q, 2) + e3 * w(q, 3)
               g1 = e1 * w(q, 4) + e2 * w(q, 5) + e3 * w(q, 6)
               g2 = e1 * w(q, 7) + e2 * w(q, 8) + e3 * w(q, 9)
               g = sqrt(g1 * g1 + g2 * g2) * d
               lo(m) = min(lo(m), f - g)
               hi(m) = max(hi(m), f + g)
            end do
         end if
         lo(m) = lo(m) - 0.5_wp * hf * d**2
         hi(m) = hi(m) + 0.5_wp * hf * d**2
         if (second) then
            lo(m) = max(lo(m), lo2 - tf * d**3 / 6.0_wp)
            hi(m) = min(hi(m), hi2 + tf * d**3 / 6.0_wp)
         end if
      end do
      q2 = 0.5_wp * (lo + hi)
      c = e(:, 1) * q2(1) + e(:, 2) * q2(2) + e(:, 3) * q2(3)
      h = 0.5_wp * (hi - lo) + margin
   end subroutine leaf_box

   !> The vectors of `leaf_box` on the grid rows of one band (rows 0..kb, columns 0..npg): for
   !> each point (flattened row-fastest per column) x = r u, X_1, X_2, Y_11, Y_12, Y_22.
   pure subroutine band_vectors(i0, trig, rg, rt, rp, h11, h12, h22, v)
      integer, intent(in) :: i0
      real(wp), intent(in) :: trig(:, 0:), rg(0:, 0:), rt(0:, 0:), rp(0:, 0:), h11(0:, 0:), h12(0:, 0:), h22(0:, 0:)
      real(wp), intent(out) :: v(0:, 0:, :)
      integer :: a, j
      real(wp) :: st, ct, sp, cp, u(3), et(3), ep(3), r
      do j = 0, size(rg, 2) - 1
         do a = 0, size(rg, 1) - 1
            st = trig(1, i0 + a)
            ct = trig(2, i0 + a)
            sp = trig(3, j)
            cp = trig(4, j)
            u = [st * cp, st * sp, ct]
            et = [ct * cp, ct * sp, -st]
            ep = [-sp, cp, 0.0_wp]
            r = rg(a, j)
            v(a, j, 1:3) = r * u
            v(a, j, 4:6) = rt(a, j) * u + r * et
            v(a, j, 7:9) = rp(a, j) * u + r * ep
            v(a, j, 10:12) = (h11(a, j) - r) * u + 2.0_wp * rt(a, j) * et
            v(a, j, 13:15) = h12(a, j) * u + rt(a, j) * ep + rp(a, j) * et
            v(a, j, 16:18) = (h22(a, j) - r) * u + 2.0_wp * rp(a, j) * ep
         end do
      end do
   end subroutine band_vectors

   !> Box of patch (l, i, j) (l < leaf_level) bounding its four children's boxes along its own
   !> axes: the mean of the children's normals and two tangents.
   pure subroutine parent_box(body, l, i, j, obb_c, obb_e, obb_h, margin)
      type(contact_body_type), intent(in) :: body
      integer, intent(in) :: l, i, j
      real(wp), intent(in) :: margin
      real(wp), intent(inout) :: obb_c(:, :), obb_e(:, :, :), obb_h(:, :)
      real(wp) :: e(3, 3), lo(3), hi(3), pc, pr, ph, th, n3(3)
      integer :: k, kch, di, dj, m
      k = patch_index(body, l, i, j)
      ! normal: mean of the children's normals (any unit vector gives a valid box)
      n3 = 0.0_wp
      do dj = 0, 1
         do di = 0, 1
            kch = patch_index(body, l + 1, 2 * i - 1 + di, 2 * j - 1 + dj)
            n3 = n3 + obb_e(:, 3, kch)
         end do
      end do
      ph = two_pi * (j - 0.5_wp) / patch_cols(l)
      th = pi * (i - 0.5_wp) / patch_rows(l)
      e = frame(n3, [sin(th) * cos(ph), sin(th) * sin(ph), cos(th)], [cos(th) * cos(ph), cos(th) * sin(ph), -sin(th)], &
                [-sin(ph), cos(ph), 0.0_wp])
      lo = huge(1.0_wp)
      hi = -huge(1.0_wp)
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
      obb_c(:, k) = matmul(e, 0.5_wp * (lo + hi))
      obb_e(:, :, k) = e
      obb_h(:, k) = 0.5_wp * (hi - lo) + margin
   end subroutine parent_box

   !> Orthonormal frame (columns) whose third axis is n normalised (the radial direction u when
   !> n is degenerate) and whose first axis is e_phi (else e_theta) made orthogonal to it; any
   !> orthonormal frame gives valid boxes.
   pure function frame(n, u, et, ep) result(e)
      real(wp), intent(in) :: n(3), u(3), et(3), ep(3)
      real(wp) :: e(3, 3)
      if (norm2(n) > 1.0e-6_wp * (1.0_wp + maxval(abs(n)))) then
         e(:, 3) = n / norm2(n)
      else
         e(:, 3) = u
      end if
      e(:, 1) = ep - dot_product(ep, e(:, 3)) * e(:, 3)
      if (norm2(e(:, 1)) < 0.1_wp) e(:, 1) = et - dot_product(et, e(:, 3)) * e(:, 3)
      e(:, 1) = e(:, 1) / norm2(e(:, 1))
      e(:, 2) = cross(e(:, 3), e(:, 1))
   end function frame

   include "anm_cross.inc"

   !> r and its angular derivatives on the grid rows i0..i1 of the regular grid
   !> theta_i = i pi/nt (i = 0..nt), phi_j = 2 pi j/np (j = 0..np, column np repeating column 0; np
   !> even): per ring the sums over degree, then the sums over order for all azimuths at once
   !> (vectorised over j), even and odd orders apart so that phi_j + pi follows from phi_j
   !> (cos m(phi + pi) = (-1)^m cos m phi). Outputs (each optional, rows i0..i1 in the first
   !> dimension) r, the gradient in the orthonormal frame (e_theta, e_phi), rt = dr/dtheta,
   !> rp = (dr/dphi)/sin theta, and the covariant Hessian in that frame, h11 = r_theta,theta,
   !> h12 = (r_theta,phi - cot(theta) r_phi)/sin theta, h22 = r_phi,phi/sin^2 theta
   !> + cot(theta) r_theta (zero on the pole rows); the Legendre equation gives
   !> h11 + h22 = -sum n(n+1) a_nm Y_nm. The derivatives come all together.
   pure subroutine synthesize_rows(shape, np, nt, i0, i1, r, rt, rp, h11, h12, h22)
      type(sh_expansion_type), intent(in) :: shape
      integer, intent(in) :: np, nt, i0, i1
      real(wp), intent(out), optional :: r(i0:, 0:), rt(i0:, 0:), rp(i0:, 0:), h11(i0:, 0:), h12(i0:, 0:), &
                                         h22(i0:, 0:)
      real(wp), allocatable :: p(:), dp(:), mps(:), cs(:, :), sn(:, :), cc(:, :), sc(:, :), acc(:, :, :), ctab(:), &
                               stab(:)
      integer, allocatable :: idx_out(:)
      integer :: nmax, i, j, m, n, k, nh, nhp, q, par, nq, jj, jb
      real(wp) :: th, st, ct, pv, a, b, v(6), t(8, 6)
      logical :: derivs

      nmax = shape%nmax
      nh = np / 2
      derivs = present(rt)
      nq = merge(6, 1, derivs)
      allocate (p(packed_size(nmax + 1)), dp(packed_size(nmax)), mps(packed_size(nmax)), idx_out(0:nmax))
      ! azimuths 0..nh padded to whole blocks of eight (0..nhp)
      nhp = 8 * (nh / 8 + 1) - 1
      allocate (cs(0:nhp, 0:nmax), sn(0:nhp, 0:nmax), cc(nq, 0:nmax), sc(nq, 0:nmax), acc(0:nhp, nq, 0:1), &
                ctab(0:np - 1), stab(0:np - 1))
      k = 1
      do m = 0, nmax
         idx_out(m) = k
         k = k + nmax - m + 1
      end do
      do j = 0, np - 1
         ctab(j) = cos(two_pi * j / np)
         stab(j) = sin(two_pi * j / np)
      end do
      do m = 0, nmax
         do j = 0, nhp
            cs(j, m) = ctab(mod(m * j, np))
            sn(j, m) = stab(mod(m * j, np))
         end do
      end do
      v = 0.0_wp
      do i = i0, i1
         th = pi * i / nt
         st = sin(th)
         ct = cos(th)
         call legendre_values(shape%table, ct, p, st)
         if (derivs) call legendre_theta_derivatives(shape%table, p, nmax, idx_out, dp, mps)
         ! per order m, cos and sin coefficients of: r; r_theta; r_phi/sin; sum n(n+1) a Y;
         ! sum m (m A_m / sin)(cos, sin); r_theta,phi
         do m = 0, nmax
            cc(:, m) = 0.0_wp
            sc(:, m) = 0.0_wp
            do n = m, nmax
               pv = p(shape%table%idx(m) + n - m)
               a = shape%a(n, m)
               b = shape%b(n, m)
               cc(1, m) = cc(1, m) + a * pv
               sc(1, m) = sc(1, m) + b * pv
               if (.not. derivs) cycle
               cc(4, m) = cc(4, m) + a * (n * (n + 1) * pv)
               sc(4, m) = sc(4, m) + b * (n * (n + 1) * pv)
               pv = dp(idx_out(m) + n - m)
               cc(2, m) = cc(2, m) + a * pv
               sc(2, m) = sc(2, m) + b * pv
               pv = mps(idx_out(m) + n - m)
               cc(3, m) = cc(3, m) + b * pv
               sc(3, m) = sc(3, m) - a * pv
            end do
            if (derivs) then
               cc(5, m) = -m * sc(3, m)
               sc(5, m) = m * cc(3, m)
               cc(6, m) = m * sc(2, m)
               sc(6, m) = -m * cc(2, m)
            end if
         end do
         if (derivs) then
            ! eight azimuths at a time, the six partial sums held together over m (each element
            ! sees the same operations in the same order as in a sweep over whole rows)
            do jb = 0, nhp, 8
               do par = 0, min(1, nmax)
                  call block_sums(cc, sc, cs(jb:jb + 7, :), sn(jb:jb + 7, :), par, nmax, t)
                  acc(jb:jb + 7, :, par) = t
               end do
            end do
         else
            do m = 0, nmax
               par = mod(m, 2)
               if (m <= 1) then
                  acc(:, 1, par) = cc(1, m) * cs(:, m) + sc(1, m) * sn(:, m)
               else
                  acc(:, 1, par) = acc(:, 1, par) + cc(1, m) * cs(:, m) + sc(1, m) * sn(:, m)
               end if
            end do
         end if
         if (nmax == 0) acc(:, :, 1) = 0.0_wp
         do j = 0, np
            jj = mod(j, np)
            if (jj <= nh) then
               v(1:nq) = acc(jj, :, 0) + acc(jj, :, 1)
            else
               v(1:nq) = acc(jj - nh, :, 0) - acc(jj - nh, :, 1)
            end if
            if (present(r)) r(i, j) = v(1)
            if (.not. derivs) cycle
            rt(i, j) = v(2)
            rp(i, j) = v(3)
            if (i == 0 .or. i == nt) then
               h11(i, j) = 0.0_wp
               h12(i, j) = 0.0_wp
               h22(i, j) = 0.0_wp
            else
               ! v(5) = sum m^2 A_m / sin (cos, sin), so r_phi,phi / sin^2 = -v(5) / sin; v(6) = r_theta,phi
               h22(i, j) = (-v(5) + ct * v(2)) / st
               h11(i, j) = -v(4) - h22(i, j)
               h12(i, j) = (v(6) - ct * v(3)) / st
            end if
         end do
      end do
   end subroutine synthesize_rows

   !> t(:, q) = sum over m = par, par + 2, ... <= nmax of cc(q, m) cs(:, m) + sc(q, m) sn(:, m)
   !> for the six quantities of synthesize_rows and eight azimuths, added in increasing m.
   pure subroutine block_sums(cc, sc, cs, sn, par, nmax, t)
      real(wp), intent(in) :: cc(:, 0:), sc(:, 0:), cs(:, 0:), sn(:, 0:)
      integer, intent(in) :: par, nmax
      real(wp), intent(out) :: t(8, 6)
      real(wp) :: t1(8), t2(8), t3(8), t4(8), t5(8), t6(8), c(8), s(8)
      integer :: m
      c = cs(:, par)
      s = sn(:, par)
      t1 = cc(1, par) * c + sc(1, par) * s
      t2 = cc(2, par) * c + sc(2, par) * s
      t3 = cc(3, par) * c + sc(3, par) * s
      t4 = cc(4, par) * c + sc(4, par) * s
      t5 = cc(5, par) * c + sc(5, par) * s
      t6 = cc(6, par) * c + sc(6, par) * s
      do m = par + 2, nmax, 2
         c = cs(:, m)
         s = sn(:, m)
         t1 = t1 + cc(1, m) * c + sc(1, m) * s
         t2 = t2 + cc(2, m) * c + sc(2, m) * s
         t3 = t3 + cc(3, m) * c + sc(3, m) * s
         t4 = t4 + cc(4, m) * c + sc(4, m) * s
         t5 = t5 + cc(5, m) * c + sc(5, m) * s
         t6 = t6 + cc(6, m) * c + sc(6, m) * s
      end do
      t(:, 1) = t1
      t(:, 2) = t2
      t(:, 3) = t3
      t(:, 4) = t4
      t(:, 5) = t5
      t(:, 6) = t6
   end subroutine block_sums
   !> Certified upper bound of the support function of the body's surface along v (body frame,
   !> |v| = 1 up to rounding): h(v) = max over surface points x of x . v <= the result (shape units).
   !> Two bodies whose supports along the line of centres u add up to less than the distance of
   !> the centres are separated by the plane normal to u: a contact test that costs one table
   !> read per body.
   pure real(wp) function support_bound(body, v, c) result(h)
      !> Body with its support table.
      type(contact_body_type), intent(in) :: body
      !> Direction, body frame.
      real(wp), intent(in) :: v(3)
      !> Its cell, support_cell(v) (the contact test reads the cell's point again in stage 2b).
      integer, intent(in) :: c
      ! |v| = 1 + delta scales h by 1 + delta; rotations keep |delta| near 1e-16
      h = real(body%supp(1, c), wp) * v(1) + real(body%supp(2, c), wp) * v(2) + real(body%supp(3, c), wp) * v(3) &
          + real(body%supp(4, c), wp) * (1.0_wp + 1.0e-9_wp) + 1.0e-12_wp * body%r_max
   end function support_bound

   !> Cube-map cell (1..6 support_n^2, a column of `supp`) of a direction: the face of its largest
   !> component, then the other two components over that one, in support_n equal steps each.
   pure integer function support_cell(v) result(c)
      !> Direction (any length > 0).
      real(wp), intent(in) :: v(3)
      c = cube_cell(support_n, v)
   end function support_cell

   include "anm_cube_cell.inc"

   !> Unit direction of face f at face coordinates (a, b) in [-1, 1] (the inverse of support_cell).
   pure function face_direction(f, a, b) result(u)
      integer, intent(in) :: f
      real(wp), intent(in) :: a, b
      real(wp) :: u(3)
      integer :: ax
      ax = (f + 1) / 2
      u(ax) = merge(1.0_wp, -1.0_wp, mod(f, 2) == 1)
      u(1 + mod(ax, 3)) = a
      u(1 + mod(ax + 1, 3)) = b
      u = u / norm2(u)
   end function face_direction

   !> The support table (`supp`). For each cube-map cell: the cap (centre u0, half-angle beta)
   !> that holds it (cell edges are great-circle arcs, so its farthest point is a corner); a
   !> surface point x0 that (nearly) attains the support along u0, rounded to single precision;
   !> and eps >= max over the cap of h(v) - x0 . v, so that h(v) <= x0 . v + eps on the cell. As
   !> x0 is about the gradient of h at u0, eps is of second order in beta. eps comes from a branch
   !> and bound over the patch boxes of the node records moved by -x0: a box's largest projection
   !> over the cap is bounded by max over the cap of c . v plus sum_i h_i max |e_i . v|, and a
   !> patch is refined into its four children (down to leaf_level) while its bound exceeds a known
   !> lower bound of the maximum.
   pure subroutine support_table(body)
      type(contact_body_type), intent(inout) :: body
      integer :: f, ia, ib, cell
      real(wp) :: u0(3), beta, x0(3), xp(3), eps
      allocate (body%supp(4, 6 * support_n**2))
      do f = 1, 6
         do ib = 0, support_n - 1
            do ia = 0, support_n - 1
               cell = 1 + ia + support_n * (ib + support_n * (f - 1))
               call cube_cap(support_n, f, ia, ib, u0, beta)
               ! x0: a stored surface point far along u0 (greedy descent), or the previous
               ! cell's when that one projects further
               call greedy_point(body, u0, x0)
               if (cell > 1) then
                  xp = real(body%supp(1:3, cell - 1), wp)
                  if (dot_product(xp, u0) > dot_product(x0, u0)) x0 = xp
               end if
               x0 = real(real(x0, sp), wp)
               call cap_search(body, u0, beta, x0, eps)
               body%supp(1:3, cell) = real(x0, sp)
               eps = max(eps, 0.0_wp) + 1.0e-12_wp * body%r_max
               body%supp(4, cell) = real(eps, sp)
               if (real(body%supp(4, cell), wp) < eps) body%supp(4, cell) = nearest(body%supp(4, cell), 1.0_sp)
            end do
         end do
      end do
   end subroutine support_table

   !> Cap (centre u0, half-angle beta) holding cell (ia, ib) of face f of a cube map of n x n
   !> cells per face: the farthest corner (cell edges are great-circle arcs) plus 1e-6 rad.
   pure subroutine cube_cap(n, f, ia, ib, u0, beta)
      integer, intent(in) :: n, f, ia, ib
      real(wp), intent(out) :: u0(3), beta
      real(wp) :: corner(3), a0, a1, b0, b1
      integer :: q
      a0 = -1.0_wp + 2.0_wp * ia / n
      a1 = -1.0_wp + 2.0_wp * (ia + 1) / n
      b0 = -1.0_wp + 2.0_wp * ib / n
      b1 = -1.0_wp + 2.0_wp * (ib + 1) / n
      u0 = face_direction(f, 0.5_wp * (a0 + a1), 0.5_wp * (b0 + b1))
      beta = 0.0_wp
      do q = 1, 4
         corner = face_direction(f, merge(a0, a1, q <= 2), merge(b0, b1, mod(q, 2) == 1))
         beta = max(beta, acos(min(1.0_wp, dot_product(u0, corner))))
      end do
      beta = min(pi, beta + 1.0e-6_wp)
   end subroutine cube_cap

   !> Certified upper bounds of r per cell of a cube map of n x n cells per face
   !> (anm_geometry_radial_bound): the largest leaf-patch bound rhi among the leaf patches whose
   !> caps meet the cell's cap, found by descending the patch tree from level 0. A body without
   !> its patch arrays gives no bounds (rb%n = 0).
   pure function radial_bound(body, n) result(rb)
      !> Body with its patch arrays.
      type(contact_body_type), intent(in) :: body
      !> Cells per face edge (16: cells of about 0.1 rad).
      integer, intent(in) :: n
      type(radial_bound_type) :: rb
      integer, parameter :: stack_size = 4 * (leaf_level + 1) * 8 + 32
      integer :: f, ia, ib, top, l, i, j, k, c, stk(3, stack_size)
      real(wp) :: u0(3), beta, cosb, sinb, hi
      if (.not. allocated(body%rhi)) return
      rb%n = n
      allocate (rb%rmax(6 * n**2))
      do f = 1, 6
         do ib = 0, n - 1
            do ia = 0, n - 1
               call cube_cap(n, f, ia, ib, u0, beta)
               cosb = cos(beta + 1.0e-9_wp)
               sinb = sin(beta + 1.0e-9_wp)
               hi = 0.0_wp
               top = 0
               do j = 1, patch_cols(0)
                  do i = 1, patch_rows(0)
                     top = top + 1
                     stk(:, top) = [0, i, j]
                  end do
               end do
               do while (top > 0)
                  l = stk(1, top)
                  i = stk(2, top)
                  j = stk(3, top)
                  top = top - 1
                  k = patch_index(body, l, i, j)
                  if (body%rhi(k) <= hi) cycle
                  if (.not. caps_meet(body%dir(:, k), body%cosa(k), body%sina(k), u0, cosb, sinb)) cycle
                  if (l == leaf_level) then
                     hi = body%rhi(k)
                     cycle
                  end if
                  do c = 0, 3
                     top = top + 1
                     stk(:, top) = [l + 1, 2 * i - 1 + mod(c, 2), 2 * j - 1 + c / 2]
                  end do
               end do
               rb%rmax(1 + ia + n * (ib + n * (f - 1))) = hi
            end do
         end do
      end do
   end function radial_bound

   !> Whether two caps (unit centres d and u, half-angles alpha and beta given by their cos and
   !> sin) may share a direction: angle(d, u) <= alpha + beta, with a rounding margin.
   pure logical function caps_meet(d, cosa, sina, u, cosb, sinb)
      real(wp), intent(in) :: d(3), cosa, sina, u(3), cosb, sinb
      ! alpha + beta > pi (its sine negative): every direction
      if (sina * cosb + cosa * sinb < 0.0_wp) then
         caps_meet = .true.
      else
         caps_meet = dot_product(d, u) >= cosa * cosb - sina * sinb - 1.0e-12_wp
      end if
   end function caps_meet

   !> A stored surface point r(u_k) u_k far along u0: a beam search that keeps, level by level,
   !> the `beam` patches whose points project furthest along u0 and goes on with their children,
   !> down to leaf_level; the best point seen.
   pure subroutine greedy_point(body, u0, x)
      type(contact_body_type), intent(in) :: body
      real(wp), intent(in) :: u0(3)
      real(wp), intent(out) :: x(3)
      integer, parameter :: beam = 4
      integer :: l, i, j, c, m, k, nkeep, nnext, ncand, keep(2, beam), nxt(2, beam)
      real(wp) :: px, best, nv(beam), y(3)
      best = -huge(1.0_wp)
      x = 0.0_wp
      nkeep = 0
      do l = 0, leaf_level
         ! level 0: every patch; deeper: the four children of each kept patch
         ncand = merge(patch_rows(0) * patch_cols(0), 4 * nkeep, l == 0)
         nnext = 0
         do m = 1, ncand
            if (l == 0) then
               i = 1 + mod(m - 1, patch_rows(0))
               j = 1 + (m - 1) / patch_rows(0)
            else
               c = mod(m - 1, 4)
               i = 2 * keep(1, (m - 1) / 4 + 1) - 1 + mod(c, 2)
               j = 2 * keep(2, (m - 1) / 4 + 1) - 1 + c / 2
            end if
            k = patch_index(body, l, i, j)
            y = body%node(nd_rc, k) * body%node(nd_dir:nd_dir + 2, k)
            px = dot_product(y, u0)
            if (px > best) then
               best = px
               x = y
            end if
            call beam_insert(px, i, j, nv, nxt, nnext)
         end do
         keep = nxt
         nkeep = nnext
      end do
   end subroutine greedy_point

   !> Keep the size(v) largest values seen in v(1:n), decreasing, with their patch indices ij.
   pure subroutine beam_insert(px, i, j, v, ij, n)
      real(wp), intent(in) :: px
      integer, intent(in) :: i, j
      real(wp), intent(inout) :: v(:)
      integer, intent(inout) :: ij(:, :), n
      integer :: p
      if (n == size(v)) then
         if (px <= v(n)) return
         p = n
      else
         n = n + 1
         p = n
      end if
      do while (p > 1)
         if (v(p - 1) >= px) exit
         v(p) = v(p - 1)
         ij(:, p) = ij(:, p - 1)
         p = p - 1
      end do
      v(p) = px
      ij(:, p) = [i, j]
   end subroutine beam_insert

   !> Upper bound `upper` of max (x - x0) . v over the surface points x and the unit vectors v
   !> within angle beta of u0: branch and bound over the patch boxes. A patch whose bound lies
   !> above both the best bound so far and 0 (about the value at v = u0 when x0 is a surface
   !> point) is replaced by its children, largest bound first; any other patch keeps its bound.
   pure subroutine cap_search(body, u0, beta, x0, upper)
      type(contact_body_type), intent(in) :: body
      real(wp), intent(in) :: u0(3), beta, x0(3)
      real(wp), intent(out) :: upper
      integer, parameter :: stack_size = 64 * (leaf_level + 1)
      integer :: k, l, i, j, top, stk(3, stack_size), c, o(4), ci(4), cj(4)
      real(wp) :: cosb, sinb, chord, ub, sub(stack_size), cub(4)
      cosb = cos(beta)
      sinb = sin(beta)
      chord = 2.0_wp * sin(0.5_wp * beta)
      upper = 0.0_wp
      top = 0
      do j = 1, patch_cols(0)
         do i = 1, patch_rows(0)
            top = top + 1
            stk(:, top) = [0, i, j]
            sub(top) = box_cap_support(body%node(:, patch_index(body, 0, i, j)), x0, u0, cosb, sinb, chord)
         end do
      end do
      do while (top > 0)
         l = stk(1, top)
         i = stk(2, top)
         j = stk(3, top)
         ub = sub(top)
         top = top - 1
         if (ub <= upper) cycle
         if (l == leaf_level) then
            upper = ub
            cycle
         end if
         do c = 1, 4
            ci(c) = 2 * i - 1 + mod(c - 1, 2)
            cj(c) = 2 * j - 1 + (c - 1) / 2
            k = patch_index(body, l + 1, ci(c), cj(c))
            cub(c) = box_cap_support(body%node(:, k), x0, u0, cosb, sinb, chord)
         end do
         ! push in increasing order of bound: the largest is refined first
         o = [1, 2, 3, 4]
         call sort4(cub, o)
         do c = 1, 4
            if (cub(o(c)) <= upper) cycle
            top = top + 1
            stk(:, top) = [l + 1, ci(o(c)), cj(o(c))]
            sub(top) = cub(o(c))
         end do
      end do
   end subroutine cap_search

   !> Indices o of four values in increasing order of v(o).
   pure subroutine sort4(v, o)
      real(wp), intent(in) :: v(4)
      integer, intent(inout) :: o(4)
      integer :: a, b, t
      do a = 2, 4
         t = o(a)
         b = a - 1
         do while (b >= 1)
            if (v(o(b)) <= v(t)) exit
            o(b + 1) = o(b)
            b = b - 1
         end do
         o(b + 1) = t
      end do
   end subroutine sort4

   !> Upper bound, over the unit vectors v within angle beta of u0, of the largest projection
   !> (x - x0) . v of a patch's box (node record: centre c, unit axes e_i, half-extents h_i):
   !> max (c - x0) . v (exact over the cap) + sum_i h_i (|e_i . u0| + chord), chord = |v - u0| max.
   pure real(wp) function box_cap_support(nd, x0, u0, cosb, sinb, chord) result(s)
      real(wp), intent(in) :: nd(:), x0(3), u0(3), cosb, sinb, chord
      real(wp) :: w(3), wn, c, e(3)
      integer :: i
      w = nd(nd_c:nd_c + 2) - x0
      wn = norm2(w)
      c = dot_product(w, u0)
      if (c >= wn * cosb) then
         s = wn
      else
         s = c * cosb + sqrt(max(0.0_wp, wn * wn - c * c)) * sinb
      end if
      s = s * (1.0_wp + 1.0e-13_wp) + 1.0e-13_wp * wn
      do i = 1, 3
         e = nd(nd_e + 3 * (i - 1):nd_e + 3 * i - 1)
         s = s + nd(nd_h + i - 1) * (abs(dot_product(e, u0)) + chord) * (1.0_wp + 1.0e-13_wp)
      end do
   end function box_cap_support

end module anm_contact_body
