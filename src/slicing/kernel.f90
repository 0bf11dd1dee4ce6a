!> The slicing kernel (thesis section 3.3): label every pixel of one or more slice rectangles with
!> the particle that contains it, or with the shell layer, for shells grown around chosen particles.
!>
!> Labelling rules (thesis 3.3): (1) a pixel in a particle and in a shell is particle; (2) shells of
!> the same layer merge (the pixel gets that layer, whichever particle's shell it is); (3) where
!> layers of different hierarchy meet, the inner layer wins. A pixel is in layer k of a particle
!> when its centre lies inside the outer surface of layer k and not inside layers < k or the
!> particle; over all particles the smallest such k wins.
!>
!> Culling. Every particle is stored in a hierarchical cell list (`anm_neighbours_cell_list`) with its
!> bounding radius rho = s max(r_max of the particle, r_max of its outermost shell). The slice
!> rectangle is tiled with squares; the cell-list query of each tile's circumscribed ball returns
!> the particles (and periodic images) that may meet the tile. A candidate is kept when its
!> bounding sphere cuts the plane, its certified extent box (body frame, rotated and scaled) cuts
!> the plane (the thesis' EOB test against a flat slice box) and its bounding disc on the plane,
!> clipped by the box's in-plane extent, covers a pixel centre. Cost: O(tiles + candidates +
!> pixels inside candidate discs), independent of the particles far from the plane.
!>
!> Labelling. Candidates are binned by pixel rows (blocks of `rows_per_block`); OpenMP threads
!> take whole blocks, and inside a block the candidates are visited in the (serial, deterministic)
!> culling order, so results do not depend on the thread count. For each pixel in a candidate's
!> disc the body-frame point y = R^T (x - c) / s is updated incrementally and tested against the
!> certified bounds first; r(y / |y|) is evaluated only between r_min and r_max.
!>
!> Stacks (`anm_slicing_stack`). All planes of a call are culled before any is labelled. A
!> shelled particle's layer surfaces share its body frame, so the layers the bounds leave open
!> are evaluated together (one Legendre recursion for all of them). A particle (shelled or not)
!> whose candidate pixel rectangles over the call's planes hold more than `table_work_factor`
!> times the nodes of a direction table gets one: certified per-direction-cell bounds of its own
!> radius and of every layer's, so pixels away from the surfaces are labelled without any
!> evaluation (the table's cells are sized for an interpolation error of about one pixel). The
!> labels are those of the plain rules: the table only skips evaluations whose outcome it proves.
!>
!> Usage:
!>     call slice_labels(planes, forms, form, shell_form, center, rotation, scale, box, .true., &
!>        & particle, layer, owner, stats, error)
module anm_slicing_kernel
   use anm_core_kinds, only: wp, i8
   use anm_core_statistics, only: median
   use anm_core_error, only: error_type, fatal_error, error_code
   use anm_core_strings, only: to_string
   use anm_neighbours_cell_list, only: cell_list_type, new_cell_list
   use anm_slicing_plane, only: slice_plane_type
   use anm_slicing_form, only: slice_form_type
   use anm_slicing_stack, only: slice_stack_type, new_slice_stack, stack_radii, stack_table_bounds, &
      & build_stack_table, curvature_bound, table_nodes
   use anm_sh_expansion, only: sh_expansion_type, new_sh_expansion_real
   implicit none
   private

   public :: slice_labels, slice_stats_type, rows_per_block, max_tiles, table_work_factor

   !> Pixel rows per unit of parallel work.
   integer, parameter :: rows_per_block = 4
   !> Largest number of tiles along one edge of the slice rectangle used for culling.
   integer, parameter :: max_tiles = 64
   !> Largest periodic image index handled per axis (images farther away are never needed).
   integer, parameter :: max_image = 8
   !> A stack gets a direction table when its candidates' pixel rectangles over all planes of a
   !> call hold more than this many times the table's nodes (each node costs about one pixel).
   real(wp), parameter :: table_work_factor = 2.0_wp

   !> Work done by a call (for benchmarks and docs).
   type :: slice_stats_type
      !> (particle, image) pairs returned by the cell-list queries (with repeats across tiles).
      integer(i8) :: queried = 0
      !> Candidates kept after the plane, extent-box and rectangle tests (summed over planes).
      integer(i8) :: candidates = 0
      !> Pixel tests (candidate, pixel) made.
      integer(i8) :: tests = 0
      !> SH evaluations made (tests not decided by the certified bounds).
      integer(i8) :: evaluations = 0
   end type slice_stats_type

   !> One particle image near a plane.
   type :: candidate_type
      integer :: id = 0
      integer :: row_lo = 1, row_hi = 0, col_lo = 1, col_hi = 0
      !> Disc centre on the plane (pixel units from the origin) and squared radius (pixels^2).
      real(wp) :: pu = 0.0_wp, pv = 0.0_wp, a2 = 0.0_wp
      !> Body-frame point of the origin and its increments per pixel along u and v.
      real(wp) :: b0(3) = 0.0_wp, bu(3) = 0.0_wp, bv(3) = 0.0_wp
   end type candidate_type

   !> The candidates of one plane.
   type :: plane_candidates_type
      type(candidate_type), allocatable :: list(:)
      integer :: n = 0
   end type plane_candidates_type

contains

   !> Label the pixels of every plane (all planes must have the same pixel counts).
   subroutine slice_labels(planes, forms, form, shell_form, center, rotation, scale, box, periodic, &
                           particle, layer, owner, stats, error)
      !> Slice rectangles (same nu and nv).
      type(slice_plane_type), intent(in) :: planes(:)
      !> Surfaces: particle forms and shell-layer outer surfaces.
      type(slice_form_type), intent(in) :: forms(:)
      !> Per particle: index of its own form in `forms`.
      integer, intent(in) :: form(:)
      !> Per particle and layer: index of the layer's outer surface in `forms`, 0 for no shell;
      !> (nlayer, np), nlayer may be 0. Layer k is meant to lie inside layer k + 1; where fitted
      !> surfaces cross, a point gets the first layer whose surface contains it.
      integer, intent(in) :: shell_form(:, :)
      !> Per particle: centre (3, np), mm, inside the box.
      real(wp), intent(in) :: center(:, :)
      !> Per particle: rotation body -> world (3, 3, np).
      real(wp), intent(in) :: rotation(:, :, :)
      !> Per particle: mm per shape unit.
      real(wp), intent(in) :: scale(:)
      !> Box edges (mm).
      real(wp), intent(in) :: box(3)
      !> Periodic boundaries (images of particles crossing a face appear in the slice).
      logical, intent(in) :: periodic
      !> Particle label per pixel (nu, nv, nplane): 1-based particle id, 0 for no particle.
      integer, intent(out) :: particle(:, :, :)
      !> Shell layer per pixel: 1..nlayer, 0 where there is no shell (or a particle).
      integer, intent(out) :: layer(:, :, :)
      !> Particle whose shell gives the pixel its layer (first in culling order among equals), 0 if none.
      integer, intent(out) :: owner(:, :, :)
      !> Work counters.
      type(slice_stats_type), intent(out) :: stats
      !> Error naming the inconsistent argument.
      type(error_type), allocatable, intent(out) :: error
      type(cell_list_type) :: cl
      type(plane_candidates_type), allocatable :: cands(:)
      type(slice_stack_type), allocatable :: stacks(:)
      real(wp), allocatable :: rho(:)
      real(wp) :: rmed
      integer, allocatable :: outer(:), stack_of(:)
      integer :: np, nl, j, k, ip

      np = size(form)
      nl = size(shell_form, 1)
      call check_arguments(planes, forms, form, shell_form, center, rotation, scale, box, particle, layer, owner, error)
      if (allocated(error)) return
      particle = 0
      layer = 0
      owner = 0
      if (np == 0) return
      ! bounding radius (over the particle and all its layers) and outermost surface of each particle
      allocate (rho(np), outer(np))
      do j = 1, np
         outer(j) = form(j)
         rho(j) = forms(form(j))%r_max
         do k = nl, 1, -1
            if (shell_form(k, j) > 0) then
               if (outer(j) == form(j)) outer(j) = shell_form(k, j)
               rho(j) = max(rho(j), forms(shell_form(k, j))%r_max)
            end if
         end do
         rho(j) = scale(j) * rho(j)
      end do
      call new_cell_list(cl, box, periodic, minval(rho), capacity=np)
      do j = 1, np
         call cl%insert(j, center(:, j), rho(j))
      end do
      allocate (cands(size(planes)))
      rmed = median(rho)
      do ip = 1, size(planes)
         call cull(planes(ip), forms, outer, center, rotation, scale, rho, rmed, cl, cands(ip)%list, cands(ip)%n, stats)
         stats%candidates = stats%candidates + cands(ip)%n
      end do
      call make_stacks(planes, cands, forms, form, shell_form, scale, stacks, stack_of)
      do ip = 1, size(planes)
         call label_plane(planes(ip), cands(ip)%list, cands(ip)%n, forms, form, shell_form, stacks, stack_of, &
                          particle(:, :, ip), layer(:, :, ip), owner(:, :, ip), stats)
      end do
   end subroutine slice_labels

   !> Stacks (anm_slicing_stack) of the particles met by the planes: one per distinct (particle
   !> form, layer forms). A shelled particle always gets one (its layers are evaluated together);
   !> a direction table is built where the candidates' pixel rectangles over all planes hold more
   !> than table_work_factor times the table's nodes, and a particle without shells gets a stack
   !> only then (a large particle: most of its pixels are decided by the table).
   subroutine make_stacks(planes, cands, forms, form, shell_form, scale, stacks, stack_of)
      type(slice_plane_type), intent(in) :: planes(:)
      type(plane_candidates_type), intent(in) :: cands(:)
      type(slice_form_type), intent(in) :: forms(:)
      integer, intent(in) :: form(:), shell_form(:, :)
      real(wp), intent(in) :: scale(:)
      type(slice_stack_type), allocatable, intent(out) :: stacks(:)
      integer, allocatable, intent(out) :: stack_of(:)
      integer, allocatable :: rep(:), head(:), chain(:), keep(:), ntab(:)
      real(wp), allocatable :: work(:), smax(:)
      type(sh_expansion_type), allocatable :: layers(:)
      type(sh_expansion_type) :: zero
      real(wp) :: h
      integer :: nl, ns, ip, ic, id, s, key, k, nt, nkeep
      logical :: shelled

      nl = size(shell_form, 1)
      allocate (stack_of(size(form)), head(2 * size(forms)), rep(16), chain(16), work(16), smax(16))
      stack_of = 0
      head = 0
      ns = 0
      ! group the candidates by key: the largest layer form (shelled) or size(forms) + form (not)
      do ip = 1, size(cands)
         do ic = 1, cands(ip)%n
            id = cands(ip)%list(ic)%id
            if (stack_of(id) == 0) then
               key = 0
               if (nl > 0) key = maxval(shell_form(:, id))
               if (key == 0) key = size(forms) + form(id)
               s = head(key)
               do while (s > 0)
                  if (form(rep(s)) == form(id)) then
                     if (nl == 0) exit
                     if (all(shell_form(:, rep(s)) == shell_form(:, id))) exit
                  end if
                  s = chain(s)
               end do
               if (s == 0) then
                  if (ns == size(rep)) then
                     rep = [rep, rep]
                     chain = [chain, chain]
                     work = [work, work]
                     smax = [smax, smax]
                  end if
                  ns = ns + 1
                  s = ns
                  rep(s) = id
                  chain(s) = head(key)
                  head(key) = s
                  work(s) = 0.0_wp
                  smax(s) = 0.0_wp
               end if
               stack_of(id) = s
               smax(s) = max(smax(s), scale(id))
            end if
            s = stack_of(id)
            work(s) = work(s) + real(cands(ip)%list(ic)%row_hi - cands(ip)%list(ic)%row_lo + 1, wp) * &
                      real(cands(ip)%list(ic)%col_hi - cands(ip)%list(ic)%col_lo + 1, wp)
         end do
      end do
      ! keep the shelled stacks and those worth a table; renumber
      allocate (keep(ns), ntab(ns), layers(nl))
      call new_sh_expansion_real(zero, reshape([0.0_wp], [1, 1]), reshape([0.0_wp], [1, 1]))
      nkeep = 0
      keep = 0
      do s = 1, ns
         id = rep(s)
         shelled = .false.
         if (nl > 0) shelled = any(shell_form(:, id) > 0)
         h = curvature_bound(forms(form(id))%shape)
         do k = 1, nl
            if (shell_form(k, id) > 0) h = max(h, curvature_bound(forms(shell_form(k, id))%shape))
         end do
         ! table intervals for an interpolation error of about one pixel (shape units)
         nt = table_nodes(h, planes(1)%pixel / smax(s))
         ntab(s) = 0
         if (work(s) > table_work_factor * (nt + 1) * (2 * nt + 1)) ntab(s) = nt
         if (shelled .or. ntab(s) > 0) then
            nkeep = nkeep + 1
            keep(s) = nkeep
         end if
      end do
      allocate (stacks(nkeep))
      do s = 1, ns
         if (keep(s) == 0) cycle
         id = rep(s)
         do k = 1, nl
            if (shell_form(k, id) > 0) then
               layers(k) = forms(shell_form(k, id))%shape
            else
               layers(k) = zero
            end if
         end do
         shelled = .false.
         if (nl > 0) shelled = any(shell_form(:, id) > 0)
         if (shelled) then
            call new_slice_stack(stacks(keep(s)), layers)
         else
            call new_slice_stack(stacks(keep(s)), layers(1:0))
         end if
         associate (st => stacks(keep(s)))
            if (ntab(s) > 0) call build_stack_table(st, forms(form(id))%shape, layers(1:st%nform), ntab(s))
         end associate
      end do
      do id = 1, size(form)
         if (stack_of(id) > 0) stack_of(id) = keep(stack_of(id))
      end do
   end subroutine make_stacks

   subroutine check_arguments(planes, forms, form, shell_form, center, rotation, scale, box, particle, layer, owner, error)
      type(slice_plane_type), intent(in) :: planes(:)
      type(slice_form_type), intent(in) :: forms(:)
      integer, intent(in) :: form(:), shell_form(:, :)
      real(wp), intent(in) :: center(:, :), rotation(:, :, :), scale(:), box(3)
      integer, intent(in) :: particle(:, :, :), layer(:, :, :), owner(:, :, :)
      type(error_type), allocatable, intent(out) :: error
      integer :: np, ip
      np = size(form)
      if (size(shell_form, 2) /= np .or. size(center, 2) /= np .or. size(rotation, 3) /= np .or. &
          size(scale) /= np .or. size(center, 1) /= 3 .or. size(rotation, 1) /= 3 .or. size(rotation, 2) /= 3) then
         call fatal_error(error, "slice: particle arrays disagree in size (form: "//to_string(np)//" particles)", &
                          error_code%value)
         return
      end if
      if (np > 0) then
         if (minval(form) < 1 .or. maxval(form) > size(forms)) then
            call fatal_error(error, "slice: particle form index out of range 1.."//to_string(size(forms)), error_code%value)
            return
         end if
         if (size(shell_form) > 0) then
            if (minval(shell_form) < 0 .or. maxval(shell_form) > size(forms)) then
               call fatal_error(error, "slice: shell form index out of range 0.."//to_string(size(forms)), &
                                error_code%value)
               return
            end if
         end if
         if (.not. all(scale > 0.0_wp)) then
            call fatal_error(error, "slice: particle scales must be positive", error_code%value)
            return
         end if
      end if
      if (.not. all(box > 0.0_wp)) then
         call fatal_error(error, "slice: box edges must be positive", error_code%value)
         return
      end if
      if (size(particle, 3) /= size(planes) .or. any(shape(layer) /= shape(particle)) .or. &
          any(shape(owner) /= shape(particle))) then
         call fatal_error(error, "slice: label arrays must be (nu, nv, nplane)", error_code%value)
         return
      end if
      do ip = 1, size(planes)
         if (planes(ip)%nu /= size(particle, 1) .or. planes(ip)%nv /= size(particle, 2)) then
            call fatal_error(error, "slice: plane "//to_string(ip)//" has "//to_string(planes(ip)%nu)//" x "// &
                             to_string(planes(ip)%nv)//" pixels, the label arrays "//to_string(size(particle, 1))// &
                             " x "//to_string(size(particle, 2)), error_code%value)
            return
         end if
      end do
   end subroutine check_arguments

   !> Label one plane from its candidates.
   subroutine label_plane(plane, cands, nc, forms, form, shell_form, stacks, stack_of, particle, layer, owner, stats)
      type(slice_plane_type), intent(in) :: plane
      type(candidate_type), intent(in) :: cands(:)
      integer, intent(in) :: nc
      type(slice_form_type), intent(in) :: forms(:)
      integer, intent(in) :: form(:), shell_form(:, :)
      type(slice_stack_type), intent(in) :: stacks(:)
      integer, intent(in) :: stack_of(:)
      integer, intent(inout) :: particle(:, :), layer(:, :), owner(:, :)
      type(slice_stats_type), intent(inout) :: stats
      integer, allocatable :: first(:), members(:), fill(:)
      integer :: nblock, ib, ic, k
      integer(i8) :: tests, evals

      ! bin candidates by row blocks (CSR), keeping culling order inside each block
      nblock = (plane%nv + rows_per_block - 1) / rows_per_block
      allocate (first(nblock + 1), fill(nblock))
      first = 0
      do ic = 1, nc
         do ib = (cands(ic)%row_lo - 1) / rows_per_block + 1, (cands(ic)%row_hi - 1) / rows_per_block + 1
            first(ib + 1) = first(ib + 1) + 1
         end do
      end do
      first(1) = 1
      do ib = 1, nblock
         first(ib + 1) = first(ib + 1) + first(ib)
      end do
      allocate (members(max(1, first(nblock + 1) - 1)))
      fill = 0
      do ic = 1, nc
         do ib = (cands(ic)%row_lo - 1) / rows_per_block + 1, (cands(ic)%row_hi - 1) / rows_per_block + 1
            members(first(ib) + fill(ib)) = ic
            fill(ib) = fill(ib) + 1
         end do
      end do
      tests = 0
      evals = 0
      !$omp parallel do default(none) schedule(dynamic, 1) private(ib, k) &
      !$omp shared(nblock, first, members, cands, plane, forms, form, shell_form, stacks, stack_of, particle, layer, &
      !$omp owner) reduction(+:tests, evals)
      do ib = 1, nblock
         do k = first(ib), first(ib + 1) - 1
            associate (cd => cands(members(k)))
               if (stack_of(cd%id) > 0) then
                  call label_block_stack(cd, (ib - 1) * rows_per_block + 1, min(plane%nv, ib * rows_per_block), &
                                         forms, form, shell_form, stacks(stack_of(cd%id)), particle, layer, owner, &
                                         tests, evals)
               else
                  call label_block(cd, (ib - 1) * rows_per_block + 1, min(plane%nv, ib * rows_per_block), forms, &
                                   form, shell_form, particle, layer, owner, tests, evals)
               end if
            end associate
         end do
      end do
      !$omp end parallel do
      stats%tests = stats%tests + tests
      stats%evaluations = stats%evaluations + evals
   end subroutine label_plane

   !> Candidates of one plane, in a deterministic order (tile by tile, cell-list order inside).
   subroutine cull(plane, forms, outer, center, rotation, scale, rho, rmed, cl, cands, nc, stats)
      type(slice_plane_type), intent(in) :: plane
      type(slice_form_type), intent(in) :: forms(:)
      integer, intent(in) :: outer(:)
      real(wp), intent(in) :: center(:, :), rotation(:, :, :), scale(:), rho(:)
      type(cell_list_type), intent(in) :: cl
      type(candidate_type), allocatable, intent(out) :: cands(:)
      integer, intent(out) :: nc
      type(slice_stats_type), intent(inout) :: stats
      integer, allocatable :: cand(:), seen(:), extra_id(:), extra_code(:)
      real(wp), allocatable :: shift(:, :)
      type(candidate_type), allocatable :: tmp(:)
      type(candidate_type) :: cd
      real(wp), intent(in) :: rmed
      real(wp) :: width, height, h, tile_center(3)
      integer :: ntu, ntv, tu, tv, nq, q, code, nextra, e
      logical :: dup, keep

      width = plane%nu * plane%pixel
      height = plane%nv * plane%pixel
      h = max(width, height) / min(max_tiles, max(1, ceiling(max(width, height) / (2.0_wp * rmed))))
      h = max(h, plane%pixel)
      ntu = max(1, ceiling(width / h))
      ntv = max(1, ceiling(height / h))
      allocate (seen(size(rho)), extra_id(16), extra_code(16), cands(64))
      seen = 0
      nextra = 0
      nc = 0
      do tv = 1, ntv
         do tu = 1, ntu
            tile_center = plane%origin + (min(tu * h, width) + (tu - 1) * h) * 0.5_wp * plane%u + &
                          (min(tv * h, height) + (tv - 1) * h) * 0.5_wp * plane%v
            call cl%query(tile_center, h * sqrt(0.5_wp), center, rho, cand, shift, nq)
            stats%queried = stats%queried + nq
            do q = 1, nq
               code = image_code(shift(:, q), cl%box)
               ! deduplicate (particle, image) pairs met by several tiles
               if (seen(cand(q)) == code) cycle
               if (seen(cand(q)) /= 0) then
                  dup = .false.
                  do e = 1, nextra
                     if (extra_id(e) == cand(q) .and. extra_code(e) == code) dup = .true.
                  end do
                  if (dup) cycle
                  if (nextra == size(extra_id)) then
                     extra_id = [extra_id, extra_id]
                     extra_code = [extra_code, extra_code]
                  end if
                  nextra = nextra + 1
                  extra_id(nextra) = cand(q)
                  extra_code(nextra) = code
               else
                  seen(cand(q)) = code
               end if
               call make_candidate(plane, forms(outer(cand(q))), cand(q), center(:, cand(q)) + shift(:, q), &
                                   rotation(:, :, cand(q)), scale(cand(q)), rho(cand(q)), cd, keep)
               if (.not. keep) cycle
               if (nc == size(cands)) then
                  allocate (tmp(2 * nc))
                  tmp(:nc) = cands(:nc)
                  call move_alloc(tmp, cands)
               end if
               nc = nc + 1
               cands(nc) = cd
            end do
         end do
      end do
   end subroutine cull

   !> The plane, extent-box and rectangle tests; on success the candidate's pixel ranges and
   !> body-frame increments.
   pure subroutine make_candidate(plane, outer, id, c, rot, s, rho, cd, keep)
      type(slice_plane_type), intent(in) :: plane
      type(slice_form_type), intent(in) :: outer
      integer, intent(in) :: id
      real(wp), intent(in) :: c(3), rot(3, 3), s, rho
      type(candidate_type), intent(out) :: cd
      logical, intent(out) :: keep
      real(wp) :: d, mn(3), mu(3), mv(3), mid(3), half(3), pd, phalf, a, pu, pv, ulo, uhi, vlo, vhi, rel(3)

      keep = .false.
      rel = c - plane%origin
      d = dot_product(plane%normal, rel)
      if (abs(d) > rho) return
      ! extent box of the outermost surface, projected on the normal and the in-plane axes
      mid = 0.5_wp * (outer%box_lo + outer%box_hi)
      half = 0.5_wp * (outer%box_hi - outer%box_lo)
      mn = matmul(plane%normal, rot)
      mu = matmul(plane%u, rot)
      mv = matmul(plane%v, rot)
      pd = d + s * dot_product(mn, mid)
      phalf = s * sum(abs(mn) * half)
      if (abs(pd) > phalf) return
      a = sqrt(max(0.0_wp, rho**2 - d**2))
      pu = dot_product(plane%u, rel)
      pv = dot_product(plane%v, rel)
      ulo = max(pu - a, pu + s * (dot_product(mu, mid) - sum(abs(mu) * half)))
      uhi = min(pu + a, pu + s * (dot_product(mu, mid) + sum(abs(mu) * half)))
      vlo = max(pv - a, pv + s * (dot_product(mv, mid) - sum(abs(mv) * half)))
      vhi = min(pv + a, pv + s * (dot_product(mv, mid) + sum(abs(mv) * half)))
      cd%col_lo = max(1, ceiling(ulo / plane%pixel + 0.5_wp))
      cd%col_hi = min(plane%nu, floor(uhi / plane%pixel + 0.5_wp))
      cd%row_lo = max(1, ceiling(vlo / plane%pixel + 0.5_wp))
      cd%row_hi = min(plane%nv, floor(vhi / plane%pixel + 0.5_wp))
      if (cd%col_lo > cd%col_hi .or. cd%row_lo > cd%row_hi) return
      cd%id = id
      cd%pu = pu / plane%pixel
      cd%pv = pv / plane%pixel
      cd%a2 = (a / plane%pixel)**2
      ! y = R^T (x - c) / s at the origin, and per pixel step along u and v
      cd%b0 = matmul(-rel, rot) / s
      cd%bu = mu * (plane%pixel / s)
      cd%bv = mv * (plane%pixel / s)
      keep = .true.
   end subroutine make_candidate

   !> Label the pixels of rows [r0, r1] covered by one candidate.
   pure subroutine label_block(cd, r0, r1, forms, form, shell_form, particle, layer, owner, tests, evals)
      type(candidate_type), intent(in) :: cd
      integer, intent(in) :: r0, r1
      type(slice_form_type), intent(in) :: forms(:)
      integer, intent(in) :: form(:), shell_form(:, :)
      integer, intent(inout) :: particle(:, :), layer(:, :), owner(:, :)
      integer(i8), intent(inout) :: tests, evals
      integer :: row, col, c0, c1, k, best, nl, fp, fk
      real(wp) :: dv, w, y(3), yrow(3)
      logical :: isin

      nl = size(shell_form, 1)
      fp = form(cd%id)
      do row = max(r0, cd%row_lo), min(r1, cd%row_hi)
         dv = (row - 0.5_wp) - cd%pv
         if (dv**2 > cd%a2) cycle
         w = sqrt(cd%a2 - dv**2)
         c0 = max(cd%col_lo, ceiling(cd%pu - w + 0.5_wp))
         c1 = min(cd%col_hi, floor(cd%pu + w + 0.5_wp))
         yrow = cd%b0 + (row - 0.5_wp) * cd%bv
         do col = c0, c1
            if (particle(col, row) /= 0) cycle
            y = yrow + (col - 0.5_wp) * cd%bu
            tests = tests + 1
            call point_test(forms(fp), y, evals, isin)
            if (isin) then
               particle(col, row) = cd%id
               layer(col, row) = 0
               owner(col, row) = 0
               cycle
            end if
            best = layer(col, row)
            if (best == 0) best = nl + 1
            do k = 1, best - 1
               fk = shell_form(k, cd%id)
               if (fk == 0) cycle
               call point_test(forms(fk), y, evals, isin)
               if (isin) then
                  layer(col, row) = k
                  owner(col, row) = cd%id
                  exit
               end if
            end do
         end do
      end do
   end subroutine label_block

   !> label_block for a particle with a stack of layers: the same rules, with the direction table
   !> deciding points far from the surfaces and the undecided layers evaluated together.
   pure subroutine label_block_stack(cd, r0, r1, forms, form, shell_form, stack, particle, layer, owner, tests, evals)
      type(candidate_type), intent(in) :: cd
      integer, intent(in) :: r0, r1
      type(slice_form_type), intent(in) :: forms(:)
      integer, intent(in) :: form(:), shell_form(:, :)
      type(slice_stack_type), intent(in) :: stack
      integer, intent(inout) :: particle(:, :), layer(:, :), owner(:, :)
      integer(i8), intent(inout) :: tests, evals
      integer :: row, col, c0, c1, k, best, nl, fp, fk, limit, hit, nundecided
      real(wp) :: dv, w, y(3), yrow(3), q2, q, lo, hp, hi, r(stack%npad)
      logical :: isin, decided

      nl = size(shell_form, 1)
      fp = form(cd%id)
      do row = max(r0, cd%row_lo), min(r1, cd%row_hi)
         dv = (row - 0.5_wp) - cd%pv
         if (dv**2 > cd%a2) cycle
         w = sqrt(cd%a2 - dv**2)
         c0 = max(cd%col_lo, ceiling(cd%pu - w + 0.5_wp))
         c1 = min(cd%col_hi, floor(cd%pu + w + 0.5_wp))
         yrow = cd%b0 + (row - 0.5_wp) * cd%bv
         do col = c0, c1
            if (particle(col, row) /= 0) cycle
            y = yrow + (col - 0.5_wp) * cd%bu
            tests = tests + 1
            q2 = y(1)**2 + y(2)**2 + y(3)**2
            decided = .false.
            if (stack%ntheta > 0 .and. q2 > forms(fp)%r_min**2) then
               q = sqrt(q2)
               call stack_table_bounds(stack, y, lo, hp, hi)
               if (q > hi) cycle                     ! outside the particle and every layer
               isin = q <= lo                        ! inside the particle
               decided = isin .or. q > hp            ! or certainly outside it
            end if
            if (.not. decided) call point_test(forms(fp), y, evals, isin)
            if (isin) then
               particle(col, row) = cd%id
               layer(col, row) = 0
               owner(col, row) = 0
               cycle
            end if
            best = layer(col, row)
            if (best == 0) best = nl + 1
            ! the first layer certainly containing the point bounds the search; layers before it
            ! that the certified bounds leave open are evaluated together
            limit = best - 1
            nundecided = 0
            do k = 1, best - 1
               fk = shell_form(k, cd%id)
               if (fk == 0) cycle
               if (q2 <= forms(fk)%r_min**2) then
                  limit = k
                  exit
               end if
               if (q2 <= forms(fk)%r_max**2) nundecided = nundecided + 1
            end do
            if (nundecided > 0) then
               call stack_radii(stack, y, r)
               evals = evals + nundecided
            end if
            hit = 0
            do k = 1, limit
               fk = shell_form(k, cd%id)
               if (fk == 0) cycle
               if (q2 <= forms(fk)%r_min**2) then
                  hit = k
                  exit
               end if
               if (q2 > forms(fk)%r_max**2) cycle
               if (sqrt(q2) <= r(k)) then
                  hit = k
                  exit
               end if
            end do
            if (hit > 0) then
               layer(col, row) = hit
               owner(col, row) = cd%id
            end if
         end do
      end do
   end subroutine label_block_stack

   !> Point-in-surface test with the certified bounds first (counts SH evaluations).
   pure subroutine point_test(f, y, evals, isin)
      type(slice_form_type), intent(in) :: f
      real(wp), intent(in) :: y(3)
      integer(i8), intent(inout) :: evals
      logical, intent(out) :: isin
      real(wp) :: q2
      q2 = y(1)**2 + y(2)**2 + y(3)**2
      if (q2 <= f%r_min**2) then
         isin = .true.
      else if (q2 > f%r_max**2) then
         isin = .false.
      else
         evals = evals + 1
         isin = sqrt(q2) <= f%shape%radius_dir(y)
      end if
   end subroutine point_test

   !> A code > 0 for the periodic image shift (multiples of the box edges).
   pure function image_code(shift, box) result(code)
      real(wp), intent(in) :: shift(3), box(3)
      integer :: code
      integer :: k(3)
      k = max(-max_image, min(max_image, nint(shift / box))) + max_image
      code = 1 + k(1) + (2 * max_image + 1) * (k(2) + (2 * max_image + 1) * k(3))
   end function image_code

end module anm_slicing_kernel
